#pragma once
// Self-calibration judged by the recursion itself: a bank of coarse filters, one per power.
//
// A backbone's volumes may be overconfident (log-probabilities k times what they should be) or
// timid (k < 1); the filter raises every frame to a power kappa to undo that. Which kappa? Each
// member of the bank runs the likelihood recursion (motion, and the frame raised to its own kappa)
// on a coarse copy of the window, and scores every frame by its one-step predictive likelihood
// under that member's own predicted belief:
//
//   P_t(kappa) = sum_x b_hat_t^kappa(x) L_t^kappa(x),   S_t(kappa) = sum_{s <= t} log P_s(kappa),
//
// L^kappa being the frame raised to w kappa (w: ETU's weight) and normalized over the crop's cells,
// e^-delta / M outside it. S is the log marginal likelihood of the route under the recursion run
// at kappa: a member whose belief locks onto the wrong place (frames too sharp whose errors their
// neighbours share) pays for it at every frame that disagrees with the lock, and a member too
// timid pays at every frame it could have predicted. The members have no MGR: its blend with the
// road prior is a forgetting that lets a belief follow errors that drift slowly along the road, so
// that frames too sharp never disagree with it; without it, frames far apart on the route must
// agree through the motion alone, and those that claim more than they know are found out.
//
// Frame t is filtered with the power the scores of frames before t favour (causal), refined by a
// parabola through the best member and its neighbours in log2 kappa; with a Gaussian prior on
// log2 kappa around 0.
//
// Each P_t is mixed with a small share of the same for a uniform belief (outlier_share), so that
// one frame unlike every other (a distinctive wrong frame) cannot decide the vote alone.
//
// The coarse window: 2 x 2 cells (1 m) and up to 8 heading bins in one (at least 16 bins kept); the
// frame max-pooled onto the same cells, so that a sharp peak is not missed between samples. Cost:
// members x (the window's cells / 4 / pooling) per step: seven members on a 256^3 window hold 7/32
// of its cells. docs/filter.md, "Self-calibration".

#include <span>
#include <vector>

#include "seqloc/filter/aligned.hpp"
#include "seqloc/filter/belief.hpp"
#include "seqloc/filter/config.hpp"
#include "seqloc/filter/types.hpp"
#include "seqloc/intake/frame.hpp"

namespace seqloc::filter {

using intake::PreparedFrame;

class PowerBank {
 public:
  /// The members' powers, in octaves: 2^-4 .. 2^2 (volumes up to 16 times too sharp and 4 times
  /// too timid are brought to within half an octave by a member).
  static constexpr int kMinOctave = -4, kMaxOctave = 2;

  explicit PowerBank(const FilterConfig& config);

  /// Starts a route: every member uniform (or pooled from `belief`, the filter's window-sized one),
  /// the scores at the prior.
  void reset();
  void reset(const BeliefVolume& belief);
  /// The filter's belief replaced by another on a new grid (a region crossing): every member takes
  /// it pooled, the scores are kept.
  void rebase(const BeliefVolume& belief);
  /// The window moved by (du, dv) whole window cells (BeliefVolume::recentre).
  void recentre(int du, int dv);
  /// Each member's motion through the odometry.
  void predict(const Odometry& odometry);
  /// Scores `frame` under each member's predicted belief, then updates each member with it.
  /// `etu_weight` multiplies the power as in the full filter.
  void update(const PreparedFrame& frame, const CropPose& crop, double etu_weight);

  /// The power for the next frame (1 before any frame).
  [[nodiscard]] double power() const { return power_; }
  [[nodiscard]] int frames() const { return frames_; }
  /// The members' powers and their scores S(kappa) + log prior(kappa).
  [[nodiscard]] std::span<const double> powers() const { return powers_; }
  [[nodiscard]] std::span<const double> scores() const { return scores_; }
  /// Member i's belief (coarse window), for tests.
  [[nodiscard]] const BeliefVolume& member(std::size_t i) const { return members_[i]; }
  /// Window bins pooled into one coarse bin, for a window of `headings` bins.
  [[nodiscard]] static int heading_pooling(int headings);

 private:
  void pool_frame(const PreparedFrame& frame);
  void sample_frame(const CropPose& crop);
  void choose_power();
  /// One member's step on the sampled frame raised to `power`: returns P_t (the predictive).
  double step_member(BeliefVolume& belief, double power, float peak, double outside_value);

  FilterConfig config_;
  int pooling_;                      ///< window bins per coarse bin
  int origin_u_ = 0, origin_v_ = 0;  ///< window cell of coarse cell 0's first cell (0 or 1)
  std::vector<double> powers_, log_prior_, scores_;
  std::vector<BeliefVolume> members_;
  BeliefVolume scratch_;
  // The frame max-pooled ([bin][v][u]), and sampled at every coarse cell ([bin][v][u]; > 0 outside
  // the crop).
  AlignedVector<float> pooled_, sampled_;
  int pooled_bins_ = 0, pooled_height_ = 0, pooled_width_ = 0;
  double pooled_cell_m_ = 0;
  double power_ = 1;
  int frames_ = 0;
};

}  // namespace seqloc::filter
