#include "seqloc/pipeline/region_window.hpp"

#include <cmath>

namespace seqloc::pipeline {

RegionWindow::RegionWindow(raster::CacheReader& cache, int width, int height)
    : cache_(&cache),
      grid_(cache.grid()),
      width_(width),
      height_(height),
      road_m_(static_cast<std::size_t>(width) * static_cast<std::size_t>(height)) {}

void RegionWindow::centre_on(double x_m, double y_m) {
  origin_u_ = static_cast<std::int64_t>(std::lround(grid_.region_u(x_m))) - width_ / 2;
  origin_v_ = static_cast<std::int64_t>(std::lround(grid_.region_v(y_m))) - height_ / 2;
  road_stale_ = true;
}

std::optional<std::array<int, 2>> RegionWindow::recentre_shift(double u, double v, double margin) const {
  const double mu = margin * width_, mv = margin * height_;
  if (u >= mu && u <= width_ - 1 - mu && v >= mv && v <= height_ - 1 - mv) return std::nullopt;
  return std::array<int, 2>{static_cast<int>(std::lround(u)) - width_ / 2, static_cast<int>(std::lround(v)) - height_ / 2};
}

void RegionWindow::shift(int du, int dv) {
  origin_u_ += du;
  origin_v_ += dv;
  road_stale_ = true;
}

void RegionWindow::move_to(std::int64_t origin_u, std::int64_t origin_v) {
  if (origin_u == origin_u_ && origin_v == origin_v_) return;
  origin_u_ = origin_u;
  origin_v_ = origin_v;
  road_stale_ = true;
}

const float* RegionWindow::road_distance_m() {
  if (road_stale_) {
    cache_->read_road_distance_m(origin_u_, origin_v_, width_, height_, road_m_, /*fill_outside=*/true);
    road_stale_ = false;
  }
  return road_m_.data();
}

}  // namespace seqloc::pipeline
