#include "seqloc/pipeline/region_window.hpp"

#include <cmath>

#include "seqloc/core/angles.hpp"

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

std::span<const float> RegionWindow::road_distance_m() {
  if (road_stale_) {
    cache_->read_road_distance_m(origin_u_, origin_v_, width_, height_, road_m_, /*fill_outside=*/true);
    road_stale_ = false;
  }
  return road_m_;
}

filter::BeliefVolume carry_belief(const filter::BeliefVolume& belief, const RegionWindow& from,
                                  const RegionWindow& to) {
  const osm::RegionProjection p_from = from.cache().metadata().projection(), p_to = to.cache().metadata().projection();
  const int W = to.width(), H = to.height(), R = belief.headings();
  filter::BeliefVolume out(W, H, R);
  const float floor_value = belief.min_value();
  double total = 0;
  for (int v = 0; v < H; ++v) {
    for (int u = 0; u < W; ++u) {
      double gamma_to = 0, gamma_from = 0;
      const osm::GeoPoint p = p_to.reverse({to.x_of(u), to.y_of(v)}, gamma_to);
      const auto g = p_from.forward(p, gamma_from);
      const auto uf = std::lround(from.u_of(g.x_m)), vf = std::lround(from.v_of(g.y_m));
      const bool inside = uf >= 0 && vf >= 0 && uf < belief.width() && vf < belief.height();
      // compass = grid heading + gamma in either CRS: bin k of `to` is bin k + shift of `from`.
      const double shift = (gamma_to - gamma_from) * R / 360.0;
      for (int k = 0; k < R; ++k) {
        float value = floor_value;
        if (inside) {
          const double src = k + shift, k0 = std::floor(src), t = src - k0;
          const int i0 = ((static_cast<int>(k0) % R) + R) % R, i1 = (i0 + 1) % R;
          const int x = static_cast<int>(uf), y = static_cast<int>(vf);
          value = static_cast<float>((1 - t) * belief.prob(x, y, i0) + t * belief.prob(x, y, i1));
        }
        out.prob(u, v, k) = value;
        total += value;
      }
    }
  }
  for (std::size_t i = 0; i < out.size(); ++i) out.data()[i] = static_cast<float>(out.data()[i] / total);
  return out;
}

filter::Pose carry_pose(const filter::Pose& pose, const RegionWindow& from, const RegionWindow& to) {
  double gamma_from = 0, gamma_to = 0;
  const osm::GeoPoint p =
      from.cache().metadata().projection().reverse({from.x_of(pose.u), from.y_of(pose.v)}, gamma_from);
  const auto g = to.cache().metadata().projection().forward(p, gamma_to);
  return {to.u_of(g.x_m), to.v_of(g.y_m), core::wrap360(pose.heading_deg + gamma_from - gamma_to)};
}

GridCrop carry_crop(const GridCrop& crop, const osm::RegionProjection& from, const osm::RegionProjection& to) {
  double gamma_from = 0, gamma_to = 0;
  const osm::GeoPoint p = from.reverse({crop.x, crop.y}, gamma_from);
  const auto g = to.forward(p, gamma_to);
  return {g.x_m, g.y_m, crop.rotation_deg + gamma_from - gamma_to};
}

}  // namespace seqloc::pipeline
