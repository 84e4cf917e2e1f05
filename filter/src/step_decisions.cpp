#include "seqloc/filter/step_decisions.hpp"

#include <cmath>
#include <limits>
#include <string>

#include "internal.hpp"
#include "seqloc/core/angles.hpp"
#include "seqloc/core/units.hpp"
#include "seqloc/filter/belief.hpp"
#include "seqloc/filter/seqloc_filter.hpp"

namespace seqloc::filter {
namespace {

const double kHalfOctaveDown = std::exp2(-0.5);
// The most the estimator may sharpen frames: two octaves (see shared_cap).
constexpr double kMaxSharpening = 4;

// The most the shared errors' factor that frames go in at rises in a frame, in octaves (it falls
// at once): a factor read from a few pairs swings, and a frame let in sharp at the top of a swing
// moves the belief at once, where one let in too flat costs little.
constexpr double kFactorRiseOctaves = 0.25;

bool half_an_octave_apart(double a, double b) { return std::abs(std::log2(a / b)) >= 0.5; }

/// now / last once `now` has moved half an octave or more from `last` (which then becomes `now`),
/// else 1: the belief is raised only by moves that matter.
double ratio_once_half_an_octave(double now, double& last) {
  if (!half_an_octave_apart(now, last)) return 1.0;
  const double ratio = now / last;
  last = now;
  return ratio;
}

}  // namespace

double route_reference_entropy(std::span<const double> entropies) {
  const std::size_t n = std::min(entropies.size(), kEtuRouteFrames);
  std::vector<double> last(entropies.end() - static_cast<std::ptrdiff_t>(n), entropies.end());
  std::nth_element(last.begin(), last.begin() + static_cast<std::ptrdiff_t>(n / 2), last.end());
  return last[n / 2];
}

StepDecisions::StepDecisions(const FilterConfig& config)
    : config_(config),
      estimator_(config.self_calibration_prior_octaves, config.self_calibration_outlier_share,
                 {config.self_calibration_hold_below_octaves, config.self_calibration_hold_above_octaves,
                  config.self_calibration_hold_share, config.self_calibration_hold_follow_octaves},
                 config.self_calibration_sharpness),
      shared_(config.self_calibration_shared_lag > 0 ? config.self_calibration_shared_lag : 2) {}

std::vector<float> gps_prior_factor(const FilterConfig& config, const std::optional<GpsFix>& gps) {
  std::vector<float> factor;
  if (!config.gps_prior || !gps) return factor;
  const int W = config.width, H = config.height;
  factor.resize(static_cast<std::size_t>(W) * static_cast<std::size_t>(H));
  const double sigma_cells = gps->sigma_m / core::kCellM;
  for (int v = 0; v < H; ++v)
    for (int u = 0; u < W; ++u) {
      const double du = u - gps->u, dv = v - gps->v;
      factor[static_cast<std::size_t>(v) * W + u] =
          static_cast<float>(std::exp(-(du * du + dv * dv) / (2 * sigma_cells * sigma_cells)));
    }
  return factor;
}

FrameResult StepDecisions::step(CellWork& work, const StepInput& input, const Odometry& odometry) {
  if (started_) {
    work.predict(odometry);
    track(odometry, last_estimate_);
  }
  FrameResult result = update(work, input, std::nullopt);
  if (last_estimate_ && started_) result.relocalized = relocalized(*last_estimate_, odometry, result.argmax);
  last_estimate_ = result.pose;
  started_ = true;
  return result;
}

FrameResult StepDecisions::update(CellWork& work, const StepInput& input,
                                  const std::optional<FrameWeighting>& weighting) {
  // Checked before anything changes: a refused step leaves the belief as it was.
  const std::size_t slice = static_cast<std::size_t>(config_.width) * static_cast<std::size_t>(config_.height);
  if (config_.mgr && input.road_distance_m.empty())
    throw FilterError("MGR is on but no road-distance window was given", ErrorCategory::usage);
  if (config_.mgr && input.road_distance_m.size() != slice) {
    throw FilterError("the road-distance window holds " + std::to_string(input.road_distance_m.size()) +
                          " values, not " + std::to_string(config_.width) + " x " + std::to_string(config_.height),
                      ErrorCategory::usage);
  }
  // Self-calibration estimates from this frame unless a weighting repeats an earlier pass: the
  // one-step criterion from the evidence gathered while the frame is multiplied in, a bank on its
  // own coarse windows after the step.
  const std::optional<double> bank = work.bank_power();
  const bool calibrating = calibrates(weighting);
  const bool estimating = calibrating && !bank;
  // Where ETU's weight does not read the powered frame's entropy, the pass that finds it is left
  // to temper(), which may find it in the tempered frame.
  const bool shape_later = calibrating && !etu_reads_powered_frame();
  work.load(input.frame, estimating);
  if (calibrating) observe(input.frame, input.crop);
  if (!weighting) join_route(input.frame);
  FrameResult result = weigh(work, input, weighting, bank, shape_later);

  // The tempered likelihood q^w on the crop, scaled by its maximum (the scale cancels in the
  // normalization): exp(w kappa (log p - log p_max)); log(1/M) - outside_crop_nats outside it.
  const auto w = static_cast<float>(result.etu_weight);
  const std::optional<FrameShape> shape =
      work.temper(input.frame, static_cast<float>(w * result.volume_power),
                  shape_later ? std::optional<double>(result.volume_power) : std::nullopt);
  if (shape) {
    result.frame_entropy = shape->entropy;
    result.weighting.peak_log_prob = shape->max_log_prob;
  }
  const float outside = static_cast<float>(
      std::exp(w * (-input.frame.log_cells - config_.outside_crop_nats - result.weighting.peak_log_prob)));

  const std::vector<float> gps_term = gps_prior_factor(config_, input.gps);
  double total = work.multiply_in(input.frame, input.crop, outside, gps_term, true, estimating);
  if (estimating) estimator_.add(work.evidence(input.frame, input.crop), sharper_nats_);
  if (!(total > 0) || !std::isfinite(total)) {
    // Belief and frame share no support that float can represent: the frame alone decides.
    total = work.multiply_in(input.frame, input.crop, outside, gps_term, false, false);
    if (!(total > 0)) throw FilterError("the frame volume has no mass inside the window");
  }
  const BeliefPeak peak = work.normalize(total, input.road_distance_m);
  if (calibrating && bank) work.bank_judge(input.frame, input.crop, result.etu_weight);
  result.peak_log_belief = std::log(peak.value);
  result.argmax = {static_cast<double>(peak.u), static_cast<double>(peak.v), bin_heading_deg(peak.k, config_.headings)};
  result.pose =
      refine(peak.u, peak.v, peak.k, config_.width, config_.height, work.position_masses(), work.cell_value());
  return result;
}

FrameResult StepDecisions::weigh(CellWork& work, const StepInput& input, const std::optional<FrameWeighting>& weighting,
                                 std::optional<double> bank, bool shape_later) {
  // Self-calibration: the frame raised to the power kappa the frames before it favour,
  // q = p^kappa / Z(kappa); q's peak and entropy come from powered_shape() here, or from temper()
  // where ETU's weight does not read them.
  const PreparedFrame& frame = input.frame;
  const bool calibrating = calibrates(weighting);
  FrameResult result;
  result.volume_power = frame_power(weighting, calibrating, bank.value_or(estimator_.power()));
  const FrameShape used = calibrating && !shape_later ? work.powered_shape(frame, result.volume_power)
                          : weighting.has_value()     ? FrameShape{weighting->peak_log_prob, frame.entropy}
                                                      : FrameShape{frame.max_log_prob, frame.entropy};
  result.frame_entropy = used.entropy;
  // ETU's weight, and self-calibration's for the frame's sharpness (selfcal/estimator.hpp).
  result.etu_weight =
      weighting ? weighting->etu_weight : etu_weight_of(used.entropy) * std::exp2(sharpness_octaves(calibrating));
  result.weighting = {result.volume_power, result.etu_weight, used.max_log_prob};
  if (calibrating) {
    // The belief raised to the ratio of the new power to the one the frames before went in at, as
    // if they had gone in at the new one (exact for a belief that is their product; motion and MGR
    // between them make it an approximation): an early lock at a power the route has since voted
    // against is undone. The bank: whenever its power has moved half an octave or more from the one
    // the belief was last raised to. The one-step criterion: once, when the hold is released, from
    // the power held until then; and whenever the shared errors' factor moves half an octave.
    const auto ratio =
        static_cast<float>(bank ? bank_belief_ratio(*bank) : belief_ratio(estimator_.power(), estimator_.held()));
    if (started_ && ratio != 1.0f) work.raise(ratio);
  }
  return result;
}

void StepDecisions::reset() {
  started_ = false;
  last_estimate_.reset();
  estimator_.reset();
  entropies_.clear();
  sharper_nats_ = 0;
  was_held_ = true;
  last_power_ = 1;
  shared_.reset();
  dead_u_ = dead_v_ = 0;
  previous_.reset();
  last_factor_ = 1;
  factor_ = 1;
}

void StepDecisions::track(const Odometry& odometry, const std::optional<Pose>& estimate) {
  previous_ = estimate;
  step_ = odometry;
  if (!estimate) return;
  double du = 0, dv = 0;
  detail::displacement_cells(odometry, estimate->heading_deg, du, dv);
  dead_u_ += du;
  dead_v_ += dv;
}

void StepDecisions::recentre(int du, int dv) {
  if (last_estimate_) {
    last_estimate_->u -= du;
    last_estimate_->v -= dv;
  }
  dead_u_ -= du;
  dead_v_ -= dv;
  if (previous_) {
    previous_->u -= du;
    previous_->v -= dv;
  }
}

void StepDecisions::observe(const PreparedFrame& frame, const CropPose& crop) {
  if (config_.self_calibration_shared_lag == 0) return;
  const Pose peak = single_frame_pose(frame, crop);
  if (previous_ && relocalized(*previous_, step_, peak)) {
    shared_.add(std::numeric_limits<double>::quiet_NaN(), 0);
  } else {
    shared_.add((peak.u - dead_u_) * core::kCellM, -(peak.v - dead_v_) * core::kCellM);
  }
  factor_ = std::min(shared_.factor(), factor_ * std::exp2(kFactorRiseOctaves));
}

double StepDecisions::shared_factor() const { return config_.self_calibration_shared_lag == 0 ? 1.0 : factor_; }

double StepDecisions::shared_cap(double estimate) const {
  const int lag = config_.self_calibration_shared_lag;
  const bool independent = lag == 0 || (shared_.pairs() >= lag && shared_factor() >= kHalfOctaveDown);
  return std::min(estimate, independent ? kMaxSharpening : 1.0);
}

double StepDecisions::frame_power(const std::optional<FrameWeighting>& weighting, bool calibrating,
                                  double estimate) const {
  return power(weighting, calibrating, shared_cap(estimate) * shared_factor());
}

double StepDecisions::shared_ratio() { return ratio_once_half_an_octave(shared_factor(), last_factor_); }

double StepDecisions::belief_ratio(double estimate, bool held) {
  return hold_ratio(shared_cap(estimate), held) * shared_ratio();
}

double StepDecisions::bank_belief_ratio(double power) { return bank_ratio(shared_cap(power)) * shared_ratio(); }

double StepDecisions::power(const std::optional<FrameWeighting>& weighting, bool calibrating, double estimate) {
  if (weighting) return weighting->volume_power;
  return calibrating ? estimate : 1.0;
}

void StepDecisions::join_route(const PreparedFrame& frame) {
  // The frame's sharpness against the route's frames before it (where the slope reads it, and
  // once there are kSharpnessFrames of them), then the frame among them. Before that the
  // sharpness is 0 both where it weighs the frame and in the evidence the slope is estimated from.
  const bool slope = config_.self_calibrate && config_.self_calibration_sharpness;
  sharper_nats_ = slope && entropies_.size() >= kSharpnessFrames
                      ? (route_reference_entropy(entropies_) - frame.entropy) * frame.log_cells
                      : 0.0;
  entropies_.push_back(frame.entropy);
  if (entropies_.size() > 2 * kEtuRouteFrames) entropies_.erase(entropies_.begin(), entropies_.end() - kEtuRouteFrames);
}

double StepDecisions::etu_weight_of(double powered_entropy) const {
  if (!config_.etu) return 1.0;
  if (!config_.etu_route_reference) return etu_weight(powered_entropy, config_.etu_reference_entropy);
  return etu_weight(entropies_.back(), route_reference_entropy(entropies_));
}

double StepDecisions::sharpness_octaves(bool calibrating) const {
  if (!calibrating || config_.self_calibration_bank) return 0.0;
  return PowerEstimator::sharpness_octaves(estimator_.slope(), sharper_nats_);
}

double StepDecisions::hold_ratio(double power, bool held) {
  if (held || !was_held_) {
    last_power_ = power;
    return 1.0;
  }
  const double ratio = power / last_power_;
  was_held_ = held;
  last_power_ = power;
  return ratio;
}

bool StepDecisions::replay_due(double power, std::span<const double> kept_powers, int replays) {
  if (replays >= kMaxReplays) return false;
  return std::any_of(kept_powers.begin(), kept_powers.end(),
                     [power](double kept) { return half_an_octave_apart(kept, power); });
}

double StepDecisions::bank_ratio(double power) { return ratio_once_half_an_octave(power, last_power_); }

Pose StepDecisions::refine(int u_star, int v_star, int k_star, int width, int height, const PositionMasses& masses,
                           const CellValue& value) const {
  const int R = config_.headings;
  Pose pose{static_cast<double>(u_star), static_cast<double>(v_star), bin_heading_deg(k_star, R)};
  if (config_.pas) {
    // x_hat = sum m(x) x / sum m(x) over the cells around x* that lie in the window.
    const int r = config_.pas_radius;
    const int u0 = std::max(0, u_star - r), u1 = std::min(width - 1, u_star + r);
    const int v0 = std::max(0, v_star - r), v1 = std::min(height - 1, v_star + r);
    std::vector<double> mass(static_cast<std::size_t>(u1 - u0 + 1) * static_cast<std::size_t>(v1 - v0 + 1));
    masses(u0, v0, u1, v1, mass);
    double sm = 0, su = 0, sv = 0;
    std::size_t i = 0;
    for (int v = v0; v <= v1; ++v) {
      for (int u = u0; u <= u1; ++u, ++i) {
        sm += mass[i];
        su += mass[i] * u;
        sv += mass[i] * v;
      }
    }
    if (sm > 0) {
      pose.u = su / sm;
      pose.v = sv / sm;
    }
  }
  if (config_.subbin_heading) {
    // Circular mean of the bin headings around th* at x*, weighted by the belief.
    double sx = 0, sy = 0;
    for (int i = -config_.subbin_half_width; i <= config_.subbin_half_width; ++i) {
      const int k = (k_star + i + R) % R;
      const double weight = value(u_star, v_star, k);
      const double h = bin_heading_deg(k, R) * core::kDegToRad;
      sx += weight * std::sin(h);
      sy += weight * std::cos(h);
    }
    pose.heading_deg = core::wrap360(std::atan2(sx, sy) / core::kDegToRad);
  }
  return pose;
}

bool StepDecisions::relocalized(const Pose& previous, const Odometry& odometry, const Pose& argmax) const {
  double du = 0, dv = 0;
  detail::displacement_cells(odometry, previous.heading_deg, du, dv);
  const double pu = previous.u + du, pv = previous.v + dv;
  return std::hypot(argmax.u - pu, argmax.v - pv) * core::kCellM > config_.relocalization_jump_m;
}

}  // namespace seqloc::filter
