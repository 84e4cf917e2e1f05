#pragma once
// A slow, obviously correct implementation of one SeqLoc step: plain loops over every cell, double
// precision, written from conventions.md section 6 and the interpolation rules stated in
// seqloc_filter.hpp, sharing no code with the fast filter beyond the half-float conversion. The
// tests run both on seeded random volumes and motions and compare them.

#include <optional>
#include <span>
#include <vector>

#include "seqloc/filter/config.hpp"
#include "seqloc/filter/seqloc_filter.hpp"
#include "seqloc/filter/types.hpp"

namespace seqloc::filter::test {

class ReferenceFilter {
 public:
  explicit ReferenceFilter(const FilterConfig& config);

  void reset_uniform();
  void reset_gaussian(double u, double v, double sigma_m);
  /// One step with the frame raised to `volume_power` first (self-calibration's estimate is not
  /// made here: the tests hand in the power the fast filter reports, and check the estimator
  /// against its own brute-force reference).
  FrameResult step(const FrameVolume& volume, const CropPose& crop, const Odometry& odometry,
                   std::span<const float> road_distance_m, const std::optional<GpsFix>& gps = std::nullopt,
                   double volume_power = 1.0);

  [[nodiscard]] double at(int u, int v, int k) const { return b_[index(u, v, k)]; }

 private:
  // step()'s five steps (conventions.md section 6).
  void predict(const Odometry& odometry);
  /// The frame's log-probabilities ([bin][v][u]) raised to r.volume_power and normalized; sets
  /// r's frame entropy and ETU weight.
  std::vector<double> weigh(const FrameVolume& volume, FrameResult& r);
  void update(const FrameVolume& volume, const std::vector<double>& logp, const CropPose& crop,
              const std::optional<GpsFix>& gps, double etu_weight);
  void blend_road_prior(std::span<const float> road_distance_m);
  void estimate(FrameResult& r) const;

  [[nodiscard]] std::size_t index(int u, int v, int k) const {
    return (static_cast<std::size_t>(k) * c_.height + static_cast<std::size_t>(v)) * c_.width + u;
  }
  FilterConfig c_;
  std::vector<double> b_;
  std::vector<double> entropies_;  // the route's given entropies (ETU's route reference)
  bool first_ = true;
};

}  // namespace seqloc::filter::test
