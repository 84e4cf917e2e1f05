#pragma once
// Smoothing (docs/filter.md, "Smoothing"): the pose of frame t given the frames after it as well
// as those before, by the two-filter formula. The forward filter (SeqLocFilter) gives
// alpha_t(x) ~ p(x | frames <= t); the backward filter, run from the route's end towards its
// start with the motion reversed, gives beta_t(x) ~ p(frames after t | x); their product over the
// same window is the posterior gamma_t ~ alpha_t * beta_t.
//
// The backward filter multiplies in each frame's likelihood exactly as the forward pass weighed it
// (self-calibration's power and ETU's weight, FrameWeighting), so nothing is estimated twice and
// the two directions judge a frame alike. Its prediction is the forward one through the inverse
// motion: beta_{t-1}(x) = (L_t beta_t)(f_t(x)), f_t the motion from t-1 to t, which is the
// backward warp through invert(odometry). With exact odometry, no motion noise, and ETU, MGR and
// self-calibration off, gamma_t is the product of every frame's likelihood aligned to t (offline
// over all frames) wherever the frames' chains stay in the window; MGR, when on, mixes each pass
// with the road prior as the forward filter does (a pass that locked onto the wrong place can
// recover).

#include "seqloc/filter/belief.hpp"
#include "seqloc/filter/config.hpp"
#include "seqloc/filter/seqloc_filter.hpp"

namespace seqloc::filter {

/// The backward pass: beta over a window of `config`, from "no frames after this one" (uniform)
/// back towards the route's start. Its window is moved by the caller, as the forward filter's is.
class BackwardFilter {
 public:
  explicit BackwardFilter(const FilterConfig& config);

  /// No frames after this one: beta uniform.
  void reset();
  /// beta_t: the frames after t, carried back to frame t (before absorb() takes frame t in).
  [[nodiscard]] const BeliefVolume& belief() const { return filter_.belief(); }

  /// Frame t's likelihood multiplied in as the forward pass weighed it (with MGR as configured;
  /// `road_distance_m` as for SeqLocFilter::step, empty when MGR is off).
  void absorb(const PreparedFrame& frame, const CropPose& crop, const FrameWeighting& weighting,
              std::span<const float> road_distance_m, const std::optional<GpsFix>& gps = std::nullopt);
  /// Back to frame t - 1 through `odometry`, the motion from t - 1 to t (frame t's), reversed.
  void step_back(const Odometry& odometry);
  /// The window moves by whole cells, as BeliefVolume::recentre.
  void recentre(int du, int dv) { filter_.recentre(du, dv); }
  /// The window moved to another grid: `beta` resampled onto the new window (same size).
  void rebase(BeliefVolume beta) { filter_.rebase(std::move(beta), std::nullopt); }

 private:
  SeqLocFilter filter_;
};

/// Frame t's smoothed estimate from alpha_t (`forward`: the forward filter's belief after frame t)
/// and beta_t (`backward`: the backward filter's before it absorbs frame t), over the same window:
/// the argmax (x*, th*) of gamma = alpha * beta, PAS's position around x* when config.pas (as
/// SeqLocFilter, on gamma), the sub-bin heading when configured, and the peak's log-posterior.
/// `posterior`, when given (of the window's shape), receives gamma as it is, not normalized (a pass
/// over the window its readers need not pay: pose_uncertainty normalizes). Where the two share
/// no mass that float can represent (each certain of a different place), alpha alone decides.
/// Throws FilterError when the shapes differ.
[[nodiscard]] FrameResult smoothed_result(const BeliefVolume& forward, const BeliefVolume& backward,
                                          const FilterConfig& config, BeliefVolume* posterior = nullptr);

}  // namespace seqloc::filter
