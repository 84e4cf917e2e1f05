#pragma once
// The decisions of a SeqLoc step (conventions.md section 6), made in this one place for every
// backend, and the step's sequence that makes them: the power a frame goes in at (self-calibration's
// one-step estimator, its hold and the shared errors' factor), ETU's weight and the route's
// reference entropy, when the belief is raised again, the GPS term, MGR's share, PAS and the sub-bin
// heading around the argmax, and the relocalization flag. The CPU filter (SeqLocFilter), the CUDA
// backend (gpu::DeviceFilter) and the smoother's backward filter run their steps through step() and
// update(); each provides only the cell work behind CellWork (cell_work.hpp), so a change to one
// rule is made once and a test of one backend's decisions is a test of all.

#include <algorithm>
#include <cstddef>
#include <optional>
#include <span>
#include <vector>

#include "seqloc/filter/cell_work.hpp"
#include "seqloc/filter/config.hpp"
#include "seqloc/filter/self_calibration.hpp"
#include "seqloc/filter/types.hpp"
#include "seqloc/intake/frame.hpp"
#include "seqloc/selfcal/shared_errors.hpp"

namespace seqloc::filter {

/// The median of the last `kEtuRouteFrames` entropies in `entropies` (which must not be empty):
/// ETU's route reference (FilterConfig::etu_route_reference).
inline constexpr std::size_t kEtuRouteFrames = 256;
[[nodiscard]] double route_reference_entropy(std::span<const double> entropies);

/// ETU weight of a frame (conventions.md section 6, step 2): w = max(1 - H, 1e-3). With a
/// reference entropy H_ref > 0 (ours, FilterConfig::etu_reference_entropy) the weight is relative
/// to a typical frame: w = clamp((1 - H) / (1 - H_ref), 1e-3, 1), so frames as sharp as H_ref or
/// sharper count fully and only flatter ones are tempered.
/// (A reference of 1, a route of uniform frames, is taken as 1 - 1e-9.)
[[nodiscard]] inline double etu_weight(double normalized_entropy, double reference_entropy = 0.0) {
  const double ref = std::min(reference_entropy, 1.0 - 1e-9);
  const double w = ref > 0 ? (1.0 - normalized_entropy) / (1.0 - ref) : 1.0 - normalized_entropy;
  return std::clamp(w, 1e-3, 1.0);
}

/// The GPS term over the window (W x H, row-major): exp(-d^2 / (2 sigma^2)) at each cell, d its
/// distance from the fix; empty when the config has no GPS prior or there is no fix. What the
/// update multiplies into every heading slice.
[[nodiscard]] std::vector<float> gps_prior_factor(const FilterConfig& config, const std::optional<GpsFix>& gps);

class StepDecisions {
 public:
  explicit StepDecisions(const FilterConfig& config);

  /// One step on `work`'s belief: predict through `odometry` (not at a route's first frame), update
  /// with the frame (below), and the relocalization flag against the last estimate.
  FrameResult step(CellWork& work, const StepInput& input, const Odometry& odometry);
  /// The update: the road window checked (FilterError, usage, before anything changes), the frame's
  /// power and ETU weight, the belief raised when self-calibration asks, the frame tempered and
  /// multiplied in with the GPS term (the frame alone where belief and frame share no support),
  /// self-calibration's evidence, the normalization with MGR, the argmax and PAS. With `weighting`
  /// the frame is weighed as given (a pass repeating an earlier one: nothing is estimated and ETU's
  /// route history is left as it is).
  FrameResult update(CellWork& work, const StepInput& input, const std::optional<FrameWeighting>& weighting);

  /// A new route: the next step does not predict; ETU's route reference, the estimator and the
  /// hold's memory start again.
  void reset();
  /// The last step's pose (window cells), if any since the last reset; `rebase` replaces it (the
  /// window moved to another grid).
  [[nodiscard]] const std::optional<Pose>& last_estimate() const { return last_estimate_; }
  void rebase(const std::optional<Pose>& last_estimate) { last_estimate_ = last_estimate; }
  /// Self-calibration's one-step estimator (its power is what the next step uses without the bank).
  [[nodiscard]] const PowerEstimator& estimator() const { return estimator_; }

  /// The power a frame goes in at: a repeated pass's, self-calibration's `estimate` while it is
  /// calibrating, else 1.
  [[nodiscard]] static double power(const std::optional<FrameWeighting>& weighting, bool calibrating, double estimate);

  /// Whether ETU's weight reads the frame raised to its power (the configured reference) rather
  /// than the frame as given (the route's reference, or no ETU): a backend that finds the powered
  /// frame's shape later in the step may then wait for it.
  [[nodiscard]] bool etu_reads_powered_frame() const { return config_.etu && !config_.etu_route_reference; }

  /// A new frame joins the route: its sharpness against the route's frames before it
  /// (sharper_nats()), then its given entropy among theirs (route_entropies()).
  void join_route(const PreparedFrame& frame);
  /// ETU's weight of the frame that joined the route last (1 with ETU off): against the route's
  /// reference, which the frame's given entropy has joined, or the configured reference with the
  /// entropy of the frame raised to its power (`powered_entropy`).
  [[nodiscard]] double etu_weight_of(double powered_entropy) const;
  /// How much sharper the frame that joined last is than the route's frames before it: the
  /// median of their given entropies less its own, in nats. 0 without self-calibration's
  /// sharpness slope, which alone reads it, and for a route's first kSharpnessFrames frames,
  /// both in their weight and in the evidence the slope is estimated from: while the belief forms,
  /// a backbone overconfident throughout predicts its sharper frames worse, and on the sample
  /// region's development draw a slope read from those frames tempered the matcher's sharp and
  /// right frames (docs/filter.md, "Frames sharper than the route's").
  [[nodiscard]] double sharper_nats() const { return sharper_nats_; }
  /// The octaves self-calibration takes off that frame's weight for its sharpness,
  /// PowerEstimator::sharpness_octaves(slope, sharper_nats()) (<= 0; the weight, 2 to this, is
  /// multiplied into ETU's): 0 unless calibrating with the one-step criterion (the bank estimates
  /// no slope).
  [[nodiscard]] double sharpness_octaves(bool calibrating) const;
  static constexpr std::size_t kSharpnessFrames = 9;

  /// The one-step criterion's hold (FilterConfig::self_calibration_hold_share): the ratio the belief
  /// is raised by at this step, from the estimator's power now and whether it is held. While held,
  /// and after the release, 1 (the frames follow the estimate); at the release, the new power over
  /// the one the belief's frames went in at, so that an early lock at a power the route has since
  /// voted against is undone. The hold is not taken again.
  [[nodiscard]] double hold_ratio(double power, bool held);
  /// The bank's rule (FilterConfig::self_calibration_bank): the ratio whenever the bank's power has
  /// moved half an octave or more from the one the belief was last raised to, else 1.
  [[nodiscard]] double bank_ratio(double power);

  /// Errors the frames share (FilterConfig::self_calibration_shared_lag; selfcal/shared_errors.hpp).
  /// Each backend tells the decisions where the route goes: `track` after each prediction (the
  /// dead-reckoned point moves by the odometry along the last estimate's heading), `recentre` with
  /// the window, and `observe` with each frame it calibrates from (its single-frame peak against
  /// that point; a peak farther than relocalization_jump_m from the last estimate moved by the
  /// odometry is left out as another place).
  void track(const Odometry& odometry, const std::optional<Pose>& estimate);
  /// The window moved by (du, dv) cells: the points the decisions keep move with it.
  void recentre(int du, int dv);
  void observe(const PreparedFrame& frame, const CropPose& crop);
  /// c = (1 - rho) / (1 + rho), the power the frames' correlation asks for on top of the
  /// estimator's (1 with the lag 0): SharedErrors::factor() followed down at once and up by at
  /// most a quarter octave a frame (a factor read from a few pairs swings: the ridge routes' read
  /// 0.33 at frame 19 and 0.99 at frame 20, when the lag read reached 10 with 9 pairs).
  [[nodiscard]] double shared_factor() const;
  /// The estimator's power as the frames' correlation lets it stand: at most 1 until the frames
  /// have shown that they do not share their errors (a factor within half an octave of 1 from at
  /// least `lag` pairs), because what the estimator reads as sharpness is what shared errors
  /// inflate; at most 4 (two octaves) after that, because a factor read from a few pairs is shrunk
  /// towards independence and the one-step estimate of frames that do share their errors runs to
  /// 12 or 16.
  [[nodiscard]] double shared_cap(double estimate) const;
  [[nodiscard]] const selfcal::SharedErrors& shared_errors() const { return shared_; }

  /// The power a frame goes in at: a repeated pass's; while calibrating, the estimator's
  /// `estimate` capped (shared_cap) and times shared_factor(); else 1.
  [[nodiscard]] double frame_power(const std::optional<FrameWeighting>& weighting, bool calibrating,
                                   double estimate) const;
  /// The ratio the belief is raised by at this step: the one-step criterion's hold_ratio (or, for
  /// the bank, bank_ratio) of the capped estimate, times the shared factor's ratio to the one the
  /// belief's frames went in at when it has moved half an octave or more.
  [[nodiscard]] double belief_ratio(double estimate, bool held);
  [[nodiscard]] double bank_belief_ratio(double power);

  /// The early replay's rule (FilterConfig::self_calibration_replay_frames): the kept frames are
  /// filtered again when any of them went in (`kept_powers`) half an octave or more away from
  /// `power`, the power of the newest frame, and the route has been replayed fewer than
  /// kMaxReplays times (`replays`).
  static constexpr int kMaxReplays = 4;
  [[nodiscard]] static bool replay_due(double power, std::span<const double> kept_powers, int replays);

  /// The step's pose from the argmax (u*, v*, k*) of a width x height x headings belief: PAS's
  /// mass-weighted mean position over the (2r + 1)^2 cells around x* that lie in the window, and the
  /// sub-bin heading (the circular mean of the bin headings around th* at x*), as the config asks.
  [[nodiscard]] Pose refine(int u_star, int v_star, int k_star, int width, int height, const PositionMasses& masses,
                            const CellValue& value) const;

  /// Whether the argmax jumped farther than FilterConfig::relocalization_jump_m from the previous
  /// estimate moved by the odometry.
  [[nodiscard]] bool relocalized(const Pose& previous, const Odometry& odometry, const Pose& argmax) const;

  /// The route's given entropies that ETU's reference reads (the last 2 x kEtuRouteFrames at most).
  [[nodiscard]] const std::vector<double>& route_entropies() const { return entropies_; }

 private:
  /// Whether a step estimates from its frame: self-calibration is on and no weighting repeats an
  /// earlier pass.
  [[nodiscard]] bool calibrates(const std::optional<FrameWeighting>& weighting) const {
    return config_.self_calibrate && !weighting;
  }
  /// The frame's power and ETU weight (the powered frame's shape now, or from temper() where ETU
  /// does not read it), and the belief raised as self-calibration asks.
  FrameResult weigh(CellWork& work, const StepInput& input, const std::optional<FrameWeighting>& weighting,
                    std::optional<double> bank, bool shape_later);
  /// shared_factor()'s ratio to the one the belief's frames went in at, when it has moved half an
  /// octave or more since (1 otherwise).
  [[nodiscard]] double shared_ratio();

  FilterConfig config_;
  PowerEstimator estimator_;
  bool started_ = false;  ///< a step has run since the last reset: the next one predicts
  std::optional<Pose> last_estimate_;
  std::vector<double> entropies_;
  double sharper_nats_ = 0;  ///< sharper_nats()
  bool was_held_ = true;   ///< the estimator's hold at the last frame
  double last_power_ = 1;  ///< the power the belief's frames went in at
  selfcal::SharedErrors shared_;
  double dead_u_ = 0, dead_v_ = 0;  ///< the dead-reckoned point, window cells
  double last_factor_ = 1;          ///< the shared factor the belief's frames went in at
  double factor_ = 1;               ///< shared_factor(): the estimate's factor, followed up slowly
  std::optional<Pose> previous_;    ///< the estimate before this step and its odometry (track), by
  Odometry step_;                   ///< which observe() judges a peak with relocalized()
};

}  // namespace seqloc::filter
