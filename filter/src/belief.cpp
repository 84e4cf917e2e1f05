#include "seqloc/filter/belief.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>

namespace seqloc::filter {

BeliefVolume::BeliefVolume(int width, int height, int headings)
    : width_(width),
      height_(height),
      headings_(headings),
      data_(static_cast<std::size_t>(width) * height * headings, 0.0f) {
  assert(width > 0 && height > 0 && headings > 0);
  set_uniform();
}

void BeliefVolume::set_uniform() {
  std::fill(data_.begin(), data_.end(), static_cast<float>(-std::log(static_cast<double>(data_.size()))));
}

void BeliefVolume::set_gaussian(double u0, double v0, double sigma_cells) {
  std::vector<double> log_g(slice_cells());
  double max = -1e300;
  for (int v = 0; v < height_; ++v) {
    for (int u = 0; u < width_; ++u) {
      const double du = u - u0, dv = v - v0;
      const double l = -(du * du + dv * dv) / (2 * sigma_cells * sigma_cells);
      log_g[static_cast<std::size_t>(v) * width_ + u] = l;
      max = std::max(max, l);
    }
  }
  double sum = 0;
  for (double l : log_g) sum += std::exp(l - max);
  const double log_norm = max + std::log(sum) + std::log(static_cast<double>(headings_));
  for (int k = 0; k < headings_; ++k) {
    float* s = slice(k);
    for (std::size_t i = 0; i < slice_cells(); ++i) s[i] = static_cast<float>(log_g[i] - log_norm);
  }
}

void BeliefVolume::recentre(int du, int dv) {
  if (du == 0 && dv == 0) return;
  const float fill = min_value();
  std::vector<float> row(static_cast<std::size_t>(width_));
  for (int k = 0; k < headings_; ++k) {
    float* s = slice(k);
    std::vector<float> copy(s, s + slice_cells());
    for (int v = 0; v < height_; ++v) {
      const int sv = v + dv;
      for (int u = 0; u < width_; ++u) {
        const int su = u + du;
        s[static_cast<std::size_t>(v) * width_ + u] =
            (su >= 0 && su < width_ && sv >= 0 && sv < height_) ? copy[static_cast<std::size_t>(sv) * width_ + su]
                                                                : fill;
      }
    }
  }
}

float BeliefVolume::min_value() const { return *std::min_element(data_.begin(), data_.end()); }

double BeliefVolume::total_probability() const {
  double sum = 0;
  for (float b : data_) sum += std::exp(static_cast<double>(b));
  return sum;
}

double BeliefVolume::position_mass(int u, int v) const {
  double sum = 0;
  for (int k = 0; k < headings_; ++k) sum += std::exp(static_cast<double>(at(u, v, k)));
  return sum;
}

}  // namespace seqloc::filter
