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

void BeliefVolume::recentre(int du, int dv) {
  if (du == 0 && dv == 0) return;
  const float fill = min_value();
  std::vector<float> copy(slice_cells());
  for (int k = 0; k < headings_; ++k) {
    float* s = slice(k);
    std::copy(s, s + slice_cells(), copy.begin());
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
