// The road prior of MGR (conventions.md section 6) over a window: q from g (core/road_prior.hpp).

#include "seqloc/filter/seqloc_filter.hpp"

#include <cmath>
#include <string>

namespace seqloc::filter {

std::vector<float> road_prior_log_q(std::span<const float> road_distance_m, int width, int height, int headings, double sigma_m) {
  const std::size_t n = static_cast<std::size_t>(width) * height;
  if (road_distance_m.size() != n) {
    throw FilterError("the road-distance window holds " + std::to_string(road_distance_m.size()) + " values, not " +
                          std::to_string(width) + " x " + std::to_string(height),
                      ErrorCategory::usage);
  }
  std::vector<double> g(n);
  double z = 0;
  for (std::size_t i = 0; i < n; ++i) {
    g[i] = road_prior_g(road_distance_m[i], sigma_m);
    z += g[i];
  }
  std::vector<float> log_q(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double q = (0.9 * (z > 0 ? g[i] / z : 0.0) + 0.1 / static_cast<double>(n)) / headings;
    log_q[i] = static_cast<float>(std::log(q));
  }
  return log_q;
}

}  // namespace seqloc::filter
