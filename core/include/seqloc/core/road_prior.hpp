#pragma once
// The road prior (conventions.md section 2): g(d) = exp(-d^2 / (2 sigma^2)) over the distance d to
// the nearest road. The one definition that MGR's share in the filter, the served road_prior
// layer and the Python module's crops use (the CUDA kernels carry a device copy of the formula,
// filter/device_math.hpp, tested equal).

#include <cmath>
#include <span>
#include <vector>

namespace seqloc::core {

/// sigma of the road prior by default: a vehicle's centre lies within a lane or two of the mapped
/// centerline, and the OSM centerline itself is off by a few metres on rural roads.
inline constexpr double kRoadPriorSigmaM = 3.0;

/// g at one distance (metres).
[[nodiscard]] inline double road_prior_g(double distance_m, double sigma_m) {
  return std::exp(-distance_m * distance_m / (2 * sigma_m * sigma_m));
}

/// g of each distance, as float: the road_prior layer of a block of road distances (runs of equal
/// distances, as far from roads, reuse one exp).
[[nodiscard]] std::vector<float> road_prior_g(std::span<const float> distance_m, double sigma_m);

}  // namespace seqloc::core
