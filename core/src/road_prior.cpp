#include "seqloc/core/road_prior.hpp"

namespace seqloc::core {

std::vector<float> road_prior_g(std::span<const float> distance_m, double sigma_m) {
  std::vector<float> g(distance_m.size());
  float last = 0, value = 1.0f;
  for (std::size_t i = 0; i < distance_m.size(); ++i) {
    if (i == 0 || distance_m[i] != last) {
      last = distance_m[i];
      value = static_cast<float>(road_prior_g(static_cast<double>(last), sigma_m));
    }
    g[i] = value;
  }
  return g;
}

}  // namespace seqloc::core
