#include "seqloc/selfcal/estimator.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Core>

namespace seqloc::selfcal {
namespace {

constexpr double kNegInf = -std::numeric_limits<double>::infinity();
constexpr double kLog2MinPower = -6, kLog2MaxPower = 4, kLog2Step = 0.125;
constexpr double kSlopeStep = 0.5;  // octaves per nat
constexpr auto kSlopes = static_cast<std::size_t>(PowerEstimator::kMaxSlope / kSlopeStep) + 1;

// f(x) for x in grid steps of `f` (linear between points, its ends beyond them); f[k] exactly at
// a whole x = k.
double interpolate(const std::vector<double>& f, double x) {
  const double last = static_cast<double>(f.size() - 1);
  const double at = std::clamp(x, 0.0, last);
  const auto i = std::min(static_cast<std::size_t>(at), f.size() - 2);
  const double w = at - static_cast<double>(i);
  return (1 - w) * f[i] + w * f[i + 1];
}

// log(exp(a) + exp(b)), either may be -inf.
double log_add(double a, double b) {
  if (a == kNegInf) return b;
  if (b == kNegInf) return a;
  const double m = std::max(a, b);
  return m + std::log(std::exp(a - m) + std::exp(b - m));
}

}  // namespace

DepthHistogram::DepthHistogram(Scale scale) : scale_(scale) {
  const auto bins = static_cast<std::size_t>(kMaxDepthNats / kBinNats) + 1;
  weight_.assign(bins * kLanes, 0);
  depth_sum_.assign(bins * kLanes, 0);
}

void DepthHistogram::clear() {
  if (used_lo_ < used_hi_) {
    const auto first = static_cast<std::ptrdiff_t>(used_lo_ * kLanes),
               last = static_cast<std::ptrdiff_t>(used_hi_ * kLanes);
    std::fill(weight_.begin() + first, weight_.begin() + last, 0);
    std::fill(depth_sum_.begin() + first, depth_sum_.begin() + last, 0);
  }
  used_lo_ = bins();
  used_hi_ = 0;
}

void DepthHistogram::add_each(std::span<const float> r, std::span<const float> w) {
  constexpr Eigen::Index kBlock = 1024;
  Eigen::Array<float, kBlock, 1> depth;
  Eigen::Array<std::int32_t, kBlock, 1> bin;
  const auto max_depth = static_cast<float>(kMaxDepthNats), per_nat = static_cast<float>(1 / kBinNats);
  const auto last = static_cast<std::int32_t>(weight_.size() / kLanes - 1);
  const auto size = static_cast<Eigen::Index>(r.size());
  for (Eigen::Index start = 0; start < size; start += kBlock) {
    const Eigen::Index len = std::min(kBlock, size - start);
    // The depths and their bins in SIMD (a NaN depth lands in some bin; its weight must be 0).
    auto d = depth.head(len);
    d = (-Eigen::Map<const Eigen::ArrayXf>(r.data() + start, len)).max(0.0f).min(max_depth);
    bin.head(len) = (d * per_nat).cast<std::int32_t>().max(0).min(last);
    used_lo_ = std::min(used_lo_, static_cast<std::size_t>(bin.head(len).minCoeff()));
    used_hi_ = std::max(used_hi_, static_cast<std::size_t>(bin.head(len).maxCoeff()) + 1);
    const float* ws = w.data() + start;
    // Neighbouring cells often share a bin: each of kLanes copies takes every kLanes-th cell, so
    // that one add need not wait for the one before it.
    for (Eigen::Index i = 0; i < len; ++i) {
      if (ws[i] > 0) {
        const double wi = ws[i];
        const auto b = static_cast<std::size_t>(bin[i]) * kLanes + static_cast<std::size_t>(i % kLanes);
        // math::depth_term's fixed point (the depth and bin came from SIMD above, equal to its own).
        weight_[b] += static_cast<std::int64_t>(wi * scale_.weight + 0.5);  // NOLINT(bugprone-incorrect-roundings)
        depth_sum_[b] +=
            static_cast<std::int64_t>(wi * depth[i] * scale_.depth + 0.5);  // NOLINT(bugprone-incorrect-roundings)
      }
    }
  }
}

void DepthHistogram::add_bins(std::span<const std::int64_t> weight, std::span<const std::int64_t> depth_sum) {
  if (weight.size() != bins() || depth_sum.size() != bins()) {
    throw EstimatorError("DepthHistogram::add_bins: " + std::to_string(weight.size()) + " and " +
                             std::to_string(depth_sum.size()) + " bins given, not " + std::to_string(bins()),
                         ErrorCategory::internal);
  }
  for (std::size_t i = 0; i < bins(); ++i) {
    weight_[i * kLanes] += weight[i];
    depth_sum_[i * kLanes] += depth_sum[i];
  }
  used_lo_ = 0;
  used_hi_ = bins();
}

void DepthHistogram::merge(const DepthHistogram& other) {
  for (std::size_t i = other.used_lo_ * kLanes; i < other.used_hi_ * kLanes; ++i) {
    weight_[i] += other.weight_[i];
    depth_sum_[i] += other.depth_sum_[i];
  }
  used_lo_ = std::min(used_lo_, other.used_lo_);
  used_hi_ = std::max(used_hi_, other.used_hi_);
}

double DepthHistogram::total() const {
  std::int64_t s = 0;
  for (std::size_t i = used_lo_ * kLanes; i < used_hi_ * kLanes; ++i) s += weight_[i];
  return static_cast<double>(s) / scale_.weight;
}

std::vector<double> DepthHistogram::log_sum_exp(std::span<const double> kappas) const {
  // The non-empty bins as (log weight, mean depth), summed stably (shifted by the largest term),
  // each kappa's terms in SIMD.
  std::vector<double> log_w, depth;
  for (std::size_t i = used_lo_ * kLanes; i < used_hi_ * kLanes; i += kLanes) {
    std::int64_t weight = 0, depth_sum = 0;
    for (std::size_t lane = 0; lane < kLanes; ++lane) {
      weight += weight_[i + lane];
      depth_sum += depth_sum_[i + lane];
    }
    if (weight > 0) {
      const double w = static_cast<double>(weight) / scale_.weight;
      log_w.push_back(std::log(w));
      depth.push_back(static_cast<double>(depth_sum) / scale_.depth / w);
    }
  }
  std::vector<double> out(kappas.size(), kNegInf);
  if (log_w.empty()) return out;
  const auto n = static_cast<Eigen::Index>(log_w.size());
  const Eigen::Map<const Eigen::ArrayXd> lw(log_w.data(), n), d(depth.data(), n);
  Eigen::ArrayXd terms(n);
  for (std::size_t k = 0; k < kappas.size(); ++k) {
    terms = lw - kappas[k] * d;
    const double shift = terms.maxCoeff();
    out[k] = shift + std::log((terms - shift).exp().sum());
  }
  return out;
}

PowerEstimator::PowerEstimator(double prior_sigma_log2, double outlier_share, Hold hold, bool sharpness)
    : outlier_share_(outlier_share), hold_(hold), slopes_(sharpness ? kSlopes : 1) {
  if (!(prior_sigma_log2 > 0) || !std::isfinite(prior_sigma_log2)) {
    throw EstimatorError(
        "self-calibration: the prior's sigma must be finite and > 0, not " + std::to_string(prior_sigma_log2),
        ErrorCategory::usage);
  }
  if (!(outlier_share >= 0 && outlier_share < 1)) {
    throw EstimatorError("self-calibration: the outlier share must be in [0, 1), not " + std::to_string(outlier_share),
                         ErrorCategory::usage);
  }
  if (!(hold.below >= 0 && hold.below <= 4) || !(hold.above >= 0 && hold.above <= 4) ||
      !(hold.follow_below >= 0 && hold.follow_below <= 10) || !(hold.share >= 0 && hold.share <= 1)) {
    throw EstimatorError(
        "self-calibration: the hold's band must reach 0 to 4 octaves each way, its share be in [0, 1] and its "
        "following reach 0 to 10 octaves, not " +
            std::to_string(hold.below) + ", " + std::to_string(hold.above) + ", " + std::to_string(hold.share) +
            " and " + std::to_string(hold.follow_below),
        ErrorCategory::usage);
  }
  const auto steps = static_cast<int>(std::lround((kLog2MaxPower - kLog2MinPower) / kLog2Step));
  for (int k = 0; k <= steps; ++k) {
    const double l = kLog2MinPower + k * kLog2Step;  // exact: the step is a power of 2
    kappas_.push_back(std::exp2(l));
    log_prior_.push_back(-0.5 * (l / prior_sigma_log2) * (l / prior_sigma_log2));
  }
  reset();
}

void PowerEstimator::reset() {
  scores_.assign(slopes_, log_prior_);
  slope_ = 0;
  power_ = mode_ = 1;
  held_ = hold_.share > 0;
  frames_ = 0;
}

std::vector<double> PowerEstimator::log_predictive(const CalibrationEvidence& e, std::span<const double> kappas) const {
  // P(kappa) = sum_in b(x) exp(kappa r(x)) / Z(kappa) + b_out exp(log_outside), with
  // Z(kappa) = sum over the frame's cells of exp(kappa r); mixed with the same for a uniform
  // belief, (1 + outside_cells exp(log_outside)) / window_cells (the crop's q summing to 1).
  const auto log_a = e.belief_in_crop.log_sum_exp(kappas);
  const auto log_z = e.frame_cells.log_sum_exp(kappas);
  const double log_out = e.belief_outside > 0 ? std::log(e.belief_outside) + e.log_outside : kNegInf;
  const double log_uniform = outlier_share_ > 0 && e.window_cells > 0
                                 ? std::log(outlier_share_) + log_add(0.0, std::log(e.outside_cells) + e.log_outside) -
                                       std::log(e.window_cells)
                                 : kNegInf;
  const double log_keep = std::log1p(-outlier_share_);
  std::vector<double> out(kappas.size());
  for (std::size_t k = 0; k < kappas.size(); ++k) {
    const double inside = log_z[k] == kNegInf ? kNegInf : log_a[k] - log_z[k];
    out[k] = log_add(log_keep + log_add(inside, log_out), log_uniform);
  }
  return out;
}

void PowerEstimator::add(const CalibrationEvidence& evidence, double sharper_nats) {
  const auto log_p = log_predictive(evidence, kappas_);
  // A frame with no finite predictive (no belief mass anywhere it can see) says nothing.
  if (std::any_of(log_p.begin(), log_p.end(), [](double x) { return !std::isfinite(x); })) return;
  // At slope b the frame went in at kappa 2^sharpness_octaves(b, s): its log P read that far down
  // the grid.
  for (std::size_t j = 0; j < slopes_; ++j) {
    const double shift = sharpness_octaves(static_cast<double>(j) * kSlopeStep, sharper_nats) / kLog2Step;
    std::vector<double>& score = scores_[j];
    for (std::size_t k = 0; k < score.size(); ++k) score[k] += interpolate(log_p, static_cast<double>(k) + shift);
  }
  ++frames_;
  // The best (slope, kappa); the first slope of equal scores, so 0 until a steeper one is better.
  // A slope is a second parameter beside kappa, and pays for it as the Bayesian information
  // criterion has it, half the log of the frames read: on frames calibrated but for a power, a
  // slope fitted to their spread of sharpness by chance would otherwise move kappa
  // (SelfCalibration/Recovers). Held at 1 (below), kappa cannot move, nothing competes with the
  // slope, and it is read without the penalty.
  const double penalty = 0.5 * std::log(static_cast<double>(frames_));
  const auto penalized = [&](std::size_t j, std::size_t k) { return scores_[j][k] - (j > 0 ? penalty : 0.0); };
  std::size_t best_j = 0, best = 0;
  for (std::size_t j = 0; j < slopes_; ++j) {
    const auto k =
        static_cast<std::size_t>(std::max_element(scores_[j].begin(), scores_[j].end()) - scores_[j].begin());
    if (penalized(j, k) > penalized(best_j, best)) {
      best_j = j;
      best = k;
    }
  }
  settle(best_j, best);
  if (power_ == 1.0 && held_) {
    // Held at 1: the slope that does best with kappa at 1.
    const auto one = static_cast<std::size_t>(std::lround(-kLog2MinPower / kLog2Step));
    best_j = 0;
    for (std::size_t j = 1; j < slopes_; ++j) {
      if (scores_[j][one] > scores_[best_j][one]) best_j = j;
    }
  }
  slope_ = static_cast<double>(best_j) * kSlopeStep;
}

void PowerEstimator::settle(std::size_t j, std::size_t best) {
  const std::vector<double>& score = scores_[j];
  double log2_power = std::log2(kappas_[best]);
  if (best > 0 && best + 1 < score.size()) {
    // The vertex of the parabola through the best point and its neighbours (within half a step).
    const double a = score[best - 1], b = score[best], c = score[best + 1];
    const double curvature = a - 2 * b + c;
    if (curvature < 0) log2_power += 0.5 * kLog2Step * (a - c) / curvature;
  }
  // The hold: power 1 as long as the posterior keeps at least hold_.share of its mass on powers
  // from hold_.below octaves under 1 to hold_.above over it; once released, released for the
  // rest of the route (the posterior hovering at the threshold would otherwise switch the power
  // back and forth).
  if (held_) {
    double inside = 0, all = 0;
    for (std::size_t k = 0; k < score.size(); ++k) {
      const double p = std::exp(score[k] - score[best]);
      all += p;
      const double l = std::log2(kappas_[k]);
      if (l >= -hold_.below - 1e-9 && l <= hold_.above + 1e-9) inside += p;
    }
    held_ = hold_.share > 0 && inside >= hold_.share * all;
  }
  // Held, a mode far below 1 is still followed: frames that much too sharp lock the belief onto a
  // wrong place within a few frames, before the evidence can be decisive, and trusting a backbone
  // less than it asks costs the recursion little.
  mode_ = std::exp2(log2_power);
  power_ = held_ && log2_power >= -hold_.follow_below ? 1.0 : mode_;
}

}  // namespace seqloc::selfcal
