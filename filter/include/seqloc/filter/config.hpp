#pragma once
// The filter's configuration: the paper's defaults, our additions off.

#include <span>
#include <string>
#include <variant>

#include "seqloc/core/road_prior.hpp"

namespace seqloc::filter {

// Fields grouped by the component they set (window, ETU, MGR, ...), not packed: one config per filter.
struct FilterConfig {  // NOLINT(clang-analyzer-optin.performance.Padding)
  // Window (conventions.md section 6).
  int width = 256;     ///< cells (0.5 m)
  int height = 256;    ///< cells
  int headings = 256;  ///< R, heading bins

  // The three components of SeqLoc; all off is the naive online recursion.
  bool etu = true;  ///< Entropy-Tempered Uncertainty
  bool mgr = true;  ///< Map-Guided Relocalization
  bool pas = true;  ///< Peak-Anchored Smoothing
  /// ETU relative to a typical frame (ours; 0 is the paper's ETU, w = 1 - H): w = clamp((1 - H) /
  /// (1 - H_ref), 1e-3, 1). Calibrated volumes are spread by design (their floor), so the paper's
  /// weights temper every frame (w ~ 0.1) and the belief hardly moves. 0.9: the median entropy of
  /// the calibrated matcher's volumes on development routes (docs/filter.md, "ETU").
  double etu_reference_entropy = 0.9;
  /// ETU relative to the route's own typical frame (ours): H_ref is the median entropy of the
  /// route's frames so far (the last 256), as given, before self-calibration's power, instead of
  /// etu_reference_entropy; the weight reads the frame's entropy as given too. A backbone whose
  /// calibrated volumes are sharper or flatter than the matcher's then keeps ETU's meaning, and
  /// self-calibration flattening a frame does not also make ETU flatten it.
  bool etu_route_reference = true;
  double mgr_epsilon = 0.01;  ///< eps of MGR
  /// sigma of the road prior g(x) = exp(-d^2 / (2 sigma^2)). 3 m: a vehicle's centre lies within
  /// a lane or two of the mapped centerline, and the OSM centerline itself is off by a few metres
  /// on rural roads; the benchmark's sigma sweep refines this per region.
  double mgr_sigma_m = core::kRoadPriorSigmaM;
  int pas_radius = 3;  ///< r of PAS, cells

  /// Window cells outside a frame's crop get the density log(1/M) - outside_crop_nats (conventions.md
  /// section 6 step 3 has 0, kept reproducible with 0). The crop is placed to contain the vehicle,
  /// so outside is less likely than an average observed cell; with 0 an unobserved cell outranks
  /// most observed ones and mass leaks out of the crop. 1: chosen on development routes
  /// (docs/filter.md, "Outside the crop").
  double outside_crop_nats = 1.0;

  /// Self-calibration at test time (ours; selfcal/estimator.hpp): each frame is raised to the power
  /// kappa that maximizes the predictive likelihood of the frames before it under the belief, so
  /// that an overconfident (or timid) backbone is tempered without ground truth.
  bool self_calibrate = true;
  /// How each power is judged: by how well the filter's own predicted belief predicts each frame
  /// at that power, with the hold below (false: the one-step criterion); or by the route's marginal
  /// likelihood under the recursion run at that power, a bank of coarse filters one per power
  /// (true; power_bank.hpp; not on the CUDA backend). Both read errors that consecutive frames
  /// share as sharpness (docs/filter.md, "Self-calibration": the ridge routes), so the bank is not
  /// the default.
  bool self_calibration_bank = false;
  /// The prior on kappa: Gaussian in log2 kappa around 0 with this sigma (octaves). It holds the
  /// estimate near 1 until the frames' evidence outweighs it.
  double self_calibration_prior_octaves = 2.0;
  /// Each frame is judged against the predicted belief mixed with this share of a uniform one:
  /// a belief locked onto the wrong place makes every good frame look overconfident, and without
  /// it would drive the power down so that the frames could no longer correct it.
  double self_calibration_outlier_share = 0.1;
  /// The one-step criterion's hold (self_calibration_bank off): the power stays exactly 1 while
  /// the posterior on it keeps at least self_calibration_hold_share of its mass on powers from
  /// self_calibration_hold_below_octaves under 1 to self_calibration_hold_above_octaves over it;
  /// released, it follows the estimate for the rest of the route. A calibrated backbone is then run
  /// as given, and a miscalibrated one is tempered once its frames show it. The band is wider
  /// above: the estimate reads frames whose errors their neighbours share as sharper than they
  /// are. Chosen on development routes (docs/filter.md, "Self-calibration").
  double self_calibration_hold_below_octaves = 0.35;
  double self_calibration_hold_above_octaves = 0.75;
  double self_calibration_hold_share = 0.05;
  /// While held, an estimate more than this many octaves under 1 is followed all the same: frames
  /// that much too sharp lock the belief onto a wrong place before the evidence is decisive.
  double self_calibration_hold_follow_octaves = 1.0;
  /// The route's first frames are filtered again at the power self-calibration settles on
  /// (pipeline::SequentialLocalizer): while the route has taken no more than this many frames,
  /// whenever a kept frame went in half an octave or more away from the power of the newest
  /// (StepDecisions::replay_due), the belief is rebuilt from the route's prior through every
  /// kept frame at that power, so that a lock made before the estimate was in is undone (at most
  /// StepDecisions::kMaxReplays times a route). 0: never. Chosen on development routes
  /// (docs/filter.md, "Self-calibration").
  int self_calibration_replay_frames = 24;
  /// Errors that consecutive frames share (selfcal/shared_errors.hpp): the frames are also raised
  /// to c = (1 - rho) / (1 + rho), rho their errors' correlation from frame to frame read from a
  /// variogram of their peaks at lags 1 and this many frames (over a route's first twice this many
  /// frames, a shorter lag, from 3; 0: off).
  int self_calibration_shared_lag = 10;
  /// Frames sharper than the route's typical frame (its median entropy) go in at up to two octaves
  /// less power, by a slope self-calibration estimates with the power (selfcal/estimator.hpp): 0,
  /// every frame at the power, unless the route's sharper frames predict worse than the rest (a
  /// backbone confidently wrong at times). The weight is multiplied into ETU's. A route's first
  /// StepDecisions::kSharpnessFrames frames have no sharpness, in their weight or in the slope's
  /// estimate. Off by default: it costs the benchmark's feature-sparse volumes when they are four
  /// or eight times too sharp (docs/filter.md, "Frames sharper than the route's").
  bool self_calibration_sharpness = false;

  /// A frame whose argmax lands farther than this from the previous estimate moved by the
  /// odometry is flagged "relocalized".
  double relocalization_jump_m = 10.0;

  // Beyond the paper, each off by default so that the paper's configuration stays reproducible.
  bool subbin_heading = false;           ///< refine th* by a circular mean over the bins around it
  int subbin_half_width = 2;             ///< bins each side of th* in that mean
  bool motion_noise = false;             ///< diffuse the predicted belief by a Gaussian growing with the step
  double motion_noise_xy_per_m = 0.05;   ///< sigma of position noise per metre driven
  double motion_noise_deg_per_m = 0.05;  ///< sigma of heading noise (degrees) per metre driven
  bool gps_prior = false;                ///< add a Gaussian position term for frames that carry a GPS fix

  int threads = 1;  ///< worker threads of one step

  /// Throws FilterError naming the field, its value and the constraint it breaks.
  void validate() const;
};

/// The seed paper's configuration (conventions.md section 6 as written): ETU w = 1 - H, unobserved
/// cells at log(1/M), no self-calibration; the other fields as in FilterConfig{}.
[[nodiscard]] FilterConfig paper_config();

/// One field of FilterConfig for the tools that set fields by name (the Python module's config
/// dict and its help, the command line's options): its name, the member, and a line saying what it
/// is (for a switch: what it turns on).
struct FilterConfigField {
  const char* name;
  std::variant<int FilterConfig::*, double FilterConfig::*, bool FilterConfig::*> member;
  const char* help;
};

/// Every field of FilterConfig, in declaration order: the one list a new field is added to.
[[nodiscard]] std::span<const FilterConfigField> filter_config_fields();

}  // namespace seqloc::filter
