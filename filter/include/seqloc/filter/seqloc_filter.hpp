#pragma once
// SeqLoc: online test-time aggregation of pose likelihood volumes (conventions.md section 6), with
// Entropy-Tempered Uncertainty, Map-Guided Relocalization and Peak-Anchored Smoothing.
//
// Interpolation (the same in the tests' reference implementation, tests/filter/reference_filter.hpp):
// - Predict warps backwards: b_hat(x, th) = b(x - d(th + yaw), th + yaw), d(h) being the odometry's
//   displacement for heading h. Each source heading slice is translated by its own sub-cell
//   displacement with bilinear interpolation, then the slices are blended linearly along the
//   circular heading axis (the yaw is in general a fraction of a bin). Both interpolations are of
//   probabilities, not log-probabilities: a geometric mean of neighbours would shed mass from
//   every peak at each step (29 % of a 2-cell-wide peak over eight moves in our tests). A cell
//   whose source lies outside the window gets the window's minimum before the step.
// - The update multiplies the belief by the tempered likelihood p^w (w from ETU), computed on the
//   frame's own cells and sampled at each window cell and bin by bilinear interpolation in space
//   and linear interpolation in heading; window cells whose centre falls outside the crop get
//   (1/M)^w. (The offline baseline interpolates probabilities too, and takes logs only to add.)

#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <span>
#include <vector>

#include "seqloc/core/road_prior.hpp"
#include "seqloc/filter/belief.hpp"
#include "seqloc/filter/cell_work.hpp"
#include "seqloc/filter/config.hpp"
#include "seqloc/filter/device_math.hpp"
#include "seqloc/filter/self_calibration.hpp"
#include "seqloc/filter/step_decisions.hpp"
#include "seqloc/filter/types.hpp"
#include "seqloc/intake/frame.hpp"

namespace seqloc::filter {

class PowerBank;

// The frame as the filter takes it, and its tempering, are the intake's (intake/frame.hpp).
using intake::intake_vector_lanes;
using intake::IntakeError;
using intake::kLogZero;
using intake::limit_intake_vector_lanes;
using intake::normalize_frame;
using intake::powered_peak_log_prob;
using intake::prepare_frame;
using intake::PreparedFrame;
using intake::summarize_frame;
using intake::temper_frame;
using intake::temper_frame_in_place;

/// The road prior of MGR before normalization (conventions.md section 6, step 4): g at a distance
/// or over a block of them, the base layer's one definition (core/road_prior.hpp).
using core::road_prior_g;

/// The road prior of MGR over the window: log q(x) for every cell (one heading's share).
/// `road_distance_m` is W x H, row-major (v, u) (FilterError when it holds another number of values).
[[nodiscard]] std::vector<float> road_prior_log_q(std::span<const float> road_distance_m, int width, int height,
                                                  int headings, double sigma_m);

class SeqLocFilter : private CellWork {
 public:
  explicit SeqLocFilter(const FilterConfig& config);
  ~SeqLocFilter() override;
  SeqLocFilter(const SeqLocFilter&) = delete;
  SeqLocFilter& operator=(const SeqLocFilter&) = delete;

  [[nodiscard]] const FilterConfig& config() const { return config_; }
  [[nodiscard]] const BeliefVolume& belief() const { return belief_; }
  /// For callers that set the belief themselves (tests, hand-made priors).
  [[nodiscard]] BeliefVolume& belief() {
    cached_min_.reset();
    return belief_;
  }

  /// Starts a sequence: the next step() does not predict, and self-calibration starts again from
  /// its prior. Uniform belief, or a Gaussian around a GPS fix (sigma in metres).
  void reset_uniform();
  void reset_gaussian(double u, double v, double sigma_m);

  /// One frame: predict through `odometry` (skipped on the first frame after a reset), update
  /// with the frame's volume at `crop`, MGR with the road distance window (W x H metres, row-major;
  /// empty when MGR is off; FilterError for another size), PAS. `gps` is used when the config
  /// enables the GPS term.
  FrameResult step(const PreparedFrame& frame, const CropPose& crop, const Odometry& odometry,
                   std::span<const float> road_distance_m, const std::optional<GpsFix>& gps = std::nullopt) {
    return decisions_.step(*this, {frame, crop, road_distance_m, gps}, odometry);
  }

  /// The stages, exposed for tests and for callers that move the window between frames.
  void predict(const Odometry& odometry) override;
  /// predict(), and the belief it moved from handed to `previous` (of the window's shape) by
  /// exchanging their storage: a replay that keeps each step's belief keeps it without a copy.
  void predict(const Odometry& odometry, BeliefVolume& previous);
  void recentre(int du, int dv);
  /// The window moved to another grid (a route crossing into the next region): `belief` is the
  /// belief resampled onto the new window (same size), `last_estimate` the last pose in its cells.
  /// Self-calibration and ETU keep what they learnt of the route.
  void rebase(BeliefVolume belief, const std::optional<Pose>& last_estimate);
  /// The last step's pose (window cells), if any since the last reset.
  [[nodiscard]] const std::optional<Pose>& last_estimate() const { return decisions_.last_estimate(); }
  /// step() without the prediction and the relocalization flag: the frame's likelihood multiplied
  /// in, MGR, the argmax and PAS. With `weighting` the frame is weighed as given (a pass repeating
  /// an earlier one: nothing is estimated, self-calibration and ETU's route history are left as
  /// they are); without it, as the configuration says.
  FrameResult update(const PreparedFrame& given, const CropPose& crop, std::span<const float> road_distance_m,
                     const std::optional<GpsFix>& gps = std::nullopt,
                     const std::optional<FrameWeighting>& weighting = std::nullopt) {
    return decisions_.update(*this, {given, crop, road_distance_m, gps}, weighting);
  }

  /// Self-calibration's one-step estimator (its power is what the next step uses when the bank is
  /// off; unused otherwise).
  [[nodiscard]] const PowerEstimator& calibration() const { return decisions_.estimator(); }
  /// Self-calibration's bank (power_bank.hpp; its power is what the next step uses), or nullptr
  /// when self-calibration or the bank is off.
  [[nodiscard]] const PowerBank* power_bank() const;

 private:
  struct Impl;
  // The cell work of a step on the CPU (cell_work.hpp), in the order StepDecisions calls it.
  void load(const PreparedFrame& frame, bool estimating) override;
  FrameShape powered_shape(const PreparedFrame& frame, double power) override;
  void raise(float ratio) override;
  std::optional<FrameShape> temper(const PreparedFrame& frame, float exponent,
                                   std::optional<double> shape_power) override;
  double multiply_in(const PreparedFrame& frame, const CropPose& crop, float outside, std::span<const float> gps_term,
                     bool with_prior, bool pool) override;
  const CalibrationEvidence& evidence(const PreparedFrame& frame, const CropPose& crop) override;
  BeliefPeak normalize(double total, std::span<const float> road_distance_m) override;
  [[nodiscard]] PositionMasses position_masses() override;
  [[nodiscard]] CellValue cell_value() override;
  [[nodiscard]] std::optional<double> bank_power() const override;
  void bank_judge(const PreparedFrame& frame, const CropPose& crop, double etu_weight) override;

  FilterConfig config_;
  BeliefVolume belief_;
  std::unique_ptr<Impl> impl_;
  std::optional<float> cached_min_;  ///< the belief's minimum, known at the end of a step
  StepDecisions decisions_;          ///< the step's decisions (step_decisions.hpp)
};

/// PAS (conventions.md section 6, step 5): the mass-weighted mean position over the
/// (2 radius + 1)^2 cells around (u, v) that lie in the window, m(x) = sum over headings of exp(b).
[[nodiscard]] Pose peak_anchored_position(const BeliefVolume& belief, int u, int v, int radius);

/// "single": the argmax of the frame's own volume, in window coordinates.
[[nodiscard]] Pose single_frame_pose(const PreparedFrame& frame, const CropPose& crop);

/// Window position (cells) of the centre of volume cell (v, u) and grid heading of bin j.
[[nodiscard]] Pose volume_cell_pose(const PreparedFrame& frame, const CropPose& crop, int v, int u, double bin);

}  // namespace seqloc::filter
