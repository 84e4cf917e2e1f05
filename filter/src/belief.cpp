#include "seqloc/filter/belief.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <cstring>

#include <Eigen/Core>

#include "seqloc/core/thread_pool.hpp"

namespace seqloc::filter {

BeliefVolume::BeliefVolume(int width, int height, int headings)
    : width_(width),
      height_(height),
      headings_(headings),
      data_(static_cast<std::size_t>(width) * height * headings, 0.0f) {
  assert(width > 0 && height > 0 && headings > 0);
  set_uniform();
}

double BeliefVolume::log_at(int u, int v, int k) const { return std::log(static_cast<double>(prob(u, v, k))); }

void BeliefVolume::set_uniform() {
  std::fill(data_.begin(), data_.end(), static_cast<float>(1.0 / static_cast<double>(data_.size())));
}

void BeliefVolume::set_gaussian(double u0, double v0, double sigma_cells) {
  std::vector<double> g(slice_cells());
  double sum = 0;
  for (int v = 0; v < height_; ++v) {
    for (int u = 0; u < width_; ++u) {
      const double du = u - u0, dv = v - v0;
      const double value = std::exp(-(du * du + dv * dv) / (2 * sigma_cells * sigma_cells));
      g[static_cast<std::size_t>(v) * width_ + u] = value;
      sum += value;
    }
  }
  const double norm = sum * headings_;
  for (int k = 0; k < headings_; ++k) {
    float* s = slice(k);
    for (std::size_t i = 0; i < slice_cells(); ++i) s[i] = static_cast<float>(g[i] / norm);
  }
}

void BeliefVolume::recentre(int du, int dv, float fill, int threads) {
  if (du == 0 && dv == 0) return;
  const int W = width_, H = height_;
  // Row v takes row v + dv, its cells u0 .. u1 from u0 + du .. u1 + du, the rest `fill`. Rows are
  // moved in the order that reads each source row before it is written (up for dv > 0, down for
  // dv < 0); memmove keeps a row's own overlap (dv = 0) right.
  const int u0 = std::max(0, -du), u1 = std::min(W, W - du);
  auto move_row = [&](float* s, int v) {
    float* row = s + static_cast<std::size_t>(v) * W;
    const int sv = v + dv;
    if (sv < 0 || sv >= H || u0 >= u1) {
      std::fill(row, row + W, fill);
      return;
    }
    std::memmove(row + u0, s + static_cast<std::size_t>(sv) * W + u0 + du,
                 static_cast<std::size_t>(u1 - u0) * sizeof(float));
    std::fill(row, row + u0, fill);
    std::fill(row + u1, row + W, fill);
  };
  core::parallel_chunks(headings_, threads, [&](int k0, int k1, int) {
    for (int k = k0; k < k1; ++k) {
      float* s = slice(k);
      if (dv >= 0) {
        for (int v = 0; v < H; ++v) move_row(s, v);
      } else {
        for (int v = H; v-- > 0;) move_row(s, v);
      }
    }
  });
}

float BeliefVolume::min_value() const {
  // A value-only reduction vectorizes; std::min_element's search for the index does not.
  return Eigen::Map<const Eigen::ArrayXf>(data_.data(), static_cast<Eigen::Index>(data_.size())).minCoeff();
}

double BeliefVolume::total_probability() const {
  double sum = 0;
  for (float p : data_) sum += p;
  return sum;
}

double BeliefVolume::position_mass(int u, int v) const {
  double sum = 0;
  for (int k = 0; k < headings_; ++k) sum += prob(u, v, k);
  return sum;
}

std::vector<float> BeliefVolume::position_marginal() const {
  std::vector<double> mass(slice_cells(), 0.0);
  for (int k = 0; k < headings_; ++k) {
    const float* p = slice(k);
    for (std::size_t i = 0; i < mass.size(); ++i) mass[i] += p[i];
  }
  return {mass.begin(), mass.end()};
}

}  // namespace seqloc::filter
