#pragma once
// Self-calibration at test time: how far to trust a backbone's volumes, estimated from the
// sequence alone (no ground truth).
//
// A volume is calibrated when, raised to the power 1, it is the probability of the true pose. A
// backbone out of its domain is overconfident (its log-probabilities are k times what they should
// be) or timid (k < 1). The filter raises every frame to a power kappa and renormalizes,
// q_kappa = p^kappa / Z(kappa), and chooses kappa by the predictive likelihood of each new frame
// under the belief predicted from the frames before it:
//
//   P_t(kappa) = sum_x b_hat_t(x) L_kappa,t(x),   S_t(kappa) = sum_{s <= t} log P_s(kappa),
//
// L being the likelihood the update multiplies in (q_kappa inside the crop, e^-delta / M outside),
// and b_hat mixed with a small uniform share (a belief may be wrong; see PowerEstimator).
// Frame t is filtered with kappa_t = argmax over kappa of S_{t-1}(kappa) + log prior(kappa): it
// depends on frames before t only. For Gaussian evidence the maximizer is the calibrated power:
// P_t is the density of the frame's peak under N(belief mean, sigma_b^2 + sigma_p^2 / kappa), whose
// expected log is largest where sigma_p^2 / kappa is the frame's true error variance. A uniform
// belief gives the same P for every kappa: frames the belief cannot judge do not move the estimate.
//
// Sharper frames may deserve less trust than the rest: a backbone confidently wrong at times is
// sharpest where it is wrong. The estimator fits a second parameter, a slope b >= 0 (octaves per
// nat): a frame s nats sharper than the route's typical frame (its entropy that much below the
// median of the route's, in nats) goes in at kappa 2^-min(b s, 2), and flatter frames at kappa (ETU
// tempers those). The score is kept on a grid of (kappa, b), b = 0 .. 2 in steps of 1/2 with a
// flat prior; a slope b > 0 must beat b = 0 by half the log of the frames read (the Bayesian
// information criterion's price of a parameter), so a route whose sharper frames predict as well
// as the rest keeps every frame at kappa. A calibrated backbone's sharper frames are its better
// ones, and b stays 0 (docs/filter.md, "Frames sharper than the route's", measures both).
//
// Cost: P_t is needed at every kappa of a grid, but depends on the frame only through its cells'
// depths r = log p - log p_max. The filter bins the belief's mass by depth while it multiplies the
// frame in (one log per window cell), and the frame's own cells by depth for Z; each kappa is
// then a sum over a few hundred bins.

#include <algorithm>
#include <cstdint>
#include <span>
#include <string>
#include <vector>

#include "seqloc/core/error.hpp"

namespace seqloc::selfcal {

/// Evidence or settings the estimator cannot take (a wrong number of bins: internal; a prior, an
/// outlier share or a hold out of range: usage).
class EstimatorError : public Error {
 public:
  explicit EstimatorError(const std::string& message, ErrorCategory category = ErrorCategory::usage)
      : Error(category, message) {}
};

/// Weights binned by depth r <= 0 (nats below a frame's peak), each bin keeping its weighted mean
/// depth, so that sum_i w_i exp(kappa r_i) is exact to second order in the bin's width. The sums
/// are kept in fixed point (integers), so that they do not depend on the order in which the
/// filter's threads add and merge them: the estimate is the same for any number of threads.
class DepthHistogram {
 public:
  static constexpr double kBinNats = 0.05;
  static constexpr double kMaxDepthNats = 200;  ///< deeper cells are counted at this depth
  /// Fixed-point scales: probability masses (summing to at most a few) in units of 2^-52; cell
  /// counts (up to 2^31) as they are, with their depths in units of 2^-20 nats.
  struct Scale {
    double weight, depth;
  };
  static constexpr Scale kMass{0x1p52, 0x1p52}, kCount{1, 0x1p20};

  explicit DepthHistogram(Scale scale = kMass);
  void clear();
  /// Adds weight w >= 0 at depth r (r > 0 is taken as 0, r < -kMaxDepthNats as -kMaxDepthNats).
  void add(double r, double w) {
    const double d = r < 0 ? std::min(-r, kMaxDepthNats) : 0.0;
    const auto bin = std::min(static_cast<std::size_t>(d * (1 / kBinNats)), weight_.size() / kLanes - 1);
    const auto i = bin * kLanes;
    used_lo_ = std::min(used_lo_, bin);
    used_hi_ = std::max(used_hi_, bin + 1);
    // w, d >= 0: the cast of x + 0.5 rounds half up, as add_each does per cell, where llround
    // would cost a call.
    weight_[i] += static_cast<std::int64_t>(w * scale_.weight + 0.5);        // NOLINT(bugprone-incorrect-roundings)
    depth_sum_[i] += static_cast<std::int64_t>(w * d * scale_.depth + 0.5);  // NOLINT(bugprone-incorrect-roundings)
  }
  /// add(r[i], w[i]) for every i, r and w of the same length (w[i] <= 0 adds nothing, whatever
  /// r[i] is, NaN included). The bins are found in SIMD, a block at a time: the filter's hot path.
  void add_each(std::span<const float> r, std::span<const float> w);
  void merge(const DepthHistogram& other);
  /// The number of depth bins.
  [[nodiscard]] static constexpr std::size_t bins() { return static_cast<std::size_t>(kMaxDepthNats / kBinNats) + 1; }
  [[nodiscard]] Scale scale() const { return scale_; }
  /// Adds per-bin sums made elsewhere (the CUDA backend's, with math::depth_term at this
  /// histogram's scale): bins() weights and depth sums in fixed point.
  void add_bins(std::span<const std::int64_t> weight, std::span<const std::int64_t> depth_sum);
  [[nodiscard]] double total() const;
  /// log sum_i w_i exp(kappa r_i) for each kappa (-inf where the histogram is empty).
  [[nodiscard]] std::vector<double> log_sum_exp(std::span<const double> kappas) const;

 private:
  static constexpr std::size_t kLanes = 4;  ///< copies of each bin (see add_each), side by side
  Scale scale_;
  std::vector<std::int64_t> weight_, depth_sum_;  ///< [bin][lane]
  // Every non-zero bin is in [used_lo_, used_hi_): clear, merge and the sums read those alone (a
  // frame's depths span a few hundred of the 4,001 bins).
  std::size_t used_lo_ = bins(), used_hi_ = 0;
};

/// One frame's evidence about the power: its own cells by depth (for Z), the predicted belief's
/// mass inside the crop by the depth of the frame there, and the belief's mass outside the crop
/// with the log-likelihood the update gives it there (log(1/M) - outside_crop_nats).
struct CalibrationEvidence {
  DepthHistogram frame_cells{DepthHistogram::kCount};
  DepthHistogram belief_in_crop;
  double belief_outside = 0;
  double log_outside = 0;
  double window_cells = 0;   ///< cells of the window (all headings)
  double outside_cells = 0;  ///< of those, the cells outside the crop
  /// Empty, as constructed (the bins' storage kept).
  void clear() {
    frame_cells.clear();
    belief_in_crop.clear();
    belief_outside = log_outside = window_cells = outside_cells = 0;
  }
};

/// The running estimate of kappa from frames' evidence, on a grid log2 kappa = -6 .. 4 in steps
/// of 1/8 with a Gaussian prior on log2 kappa around 0: the posterior's mode, refined by a
/// parabola through the best grid point and its neighbours; and of the sharpness slope b (above).
class PowerEstimator {
 public:
  /// prior_sigma_log2: the prior's sigma in octaves of kappa (> 0). outlier_share rho in [0, 1):
  /// each frame is judged against (1 - rho) b_hat + rho u, u uniform over the window, so that a
  /// belief that has locked onto the wrong place (against which every good frame looks
  /// overconfident) cannot drive the power down without bound.
  /// The hold: kappa stays exactly 1 while the posterior keeps at least `share` of its mass on
  /// powers from `below` octaves under 1 to `above` octaves over it, and is the posterior's mode
  /// once it does not, for the rest of the route (share 0: no hold). While held, a mode more than
  /// `follow_below` octaves under 1 is followed all the same.
  struct Hold {
    double below, above, share, follow_below;
  };
  /// `sharpness`: estimate the sharpness slope (false: it stays 0, the estimator of kappa alone).
  PowerEstimator(double prior_sigma_log2, double outlier_share, Hold hold = Hold{0, 0, 0, 0}, bool sharpness = true);

  /// kappa for the next frame: from the frames added so far and the prior (1 before any).
  [[nodiscard]] double power() const { return power_; }
  /// Whether the hold holds power() at 1 (the frames have not shown the backbone miscalibrated).
  [[nodiscard]] bool held() const { return held_; }
  /// The posterior's mode: power() without the hold.
  [[nodiscard]] double mode() const { return mode_; }
  [[nodiscard]] int frames() const { return frames_; }
  /// Adds log P_t(kappa) at every grid kappa and updates power() and slope(); `sharper_nats`:
  /// how much sharper the frame is than the route's typical frame (sharpness_octaves()).
  void add(const CalibrationEvidence& evidence, double sharper_nats = 0);
  /// The sharpness slope b (octaves per nat, 0 .. kMaxSlope): with the power held, the best with
  /// kappa at 1; else the best jointly with kappa, a slope > 0 paying half the log of the frames
  /// read.
  [[nodiscard]] double slope() const { return slope_; }
  static constexpr double kMaxSlope = 2;
  /// The most a frame's sharpness takes off its power, in octaves.
  static constexpr double kMaxSharpnessOctaves = 2;
  /// log2 of the factor on kappa of a frame `sharper_nats` sharper than the route's typical frame
  /// at slope b: -min(b s, kMaxSharpnessOctaves) for s > 0, 0 for frames as sharp or flatter.
  [[nodiscard]] static double sharpness_octaves(double slope, double sharper_nats) {
    return -std::clamp(slope * sharper_nats, 0.0, kMaxSharpnessOctaves);
  }
  /// log P(kappa) of one frame at each kappa (for tests and diagnostics), up to a constant that
  /// does not depend on kappa (the belief's total mass).
  [[nodiscard]] std::vector<double> log_predictive(const CalibrationEvidence& evidence,
                                                   std::span<const double> kappas) const;
  [[nodiscard]] std::span<const double> grid() const { return kappas_; }
  /// S(kappa) + log prior at each grid point, at slope 0.
  [[nodiscard]] std::span<const double> score() const { return scores_.front(); }
  void reset();

 private:
  double outlier_share_;
  Hold hold_;
  /// The power and the hold from the score at slope index j.
  void settle(std::size_t j, std::size_t best);

  std::vector<double> kappas_, log_prior_;
  std::vector<std::vector<double>> scores_;  ///< [slope index][kappa]: S + log prior
  std::size_t slopes_;                       ///< slope grid points (1 without the slope)
  double slope_ = 0;
  double power_ = 1, mode_ = 1;
  bool held_ = true;
  int frames_ = 0;
};

}  // namespace seqloc::selfcal
