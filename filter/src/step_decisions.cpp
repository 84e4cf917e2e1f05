#include "seqloc/filter/step_decisions.hpp"

#include <cmath>
#include <limits>

#include "internal.hpp"
#include "seqloc/core/angles.hpp"
#include "seqloc/core/units.hpp"
#include "seqloc/filter/belief.hpp"
#include "seqloc/filter/seqloc_filter.hpp"

namespace seqloc::filter {
namespace {

const double kHalfOctaveDown = std::exp2(-0.5);

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

void StepDecisions::reset() {
  entropies_.clear();
  was_held_ = true;
  last_power_ = 1;
  shared_.reset();
  dead_u_ = dead_v_ = 0;
  previous_.reset();
  last_factor_ = 1;
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
    return;
  }
  shared_.add((peak.u - dead_u_) * core::kCellM, -(peak.v - dead_v_) * core::kCellM);
}

double StepDecisions::shared_factor() const {
  return config_.self_calibration_shared_lag == 0 ? 1.0 : shared_.factor();
}

double StepDecisions::shared_cap(double estimate) const {
  const int lag = config_.self_calibration_shared_lag;
  const bool independent = lag == 0 || (shared_.pairs() >= lag && shared_factor() >= kHalfOctaveDown);
  return independent ? estimate : std::min(estimate, 1.0);
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

double StepDecisions::etu_weight_of(double given_entropy, double powered_entropy) {
  if (!config_.etu) return 1.0;
  if (!config_.etu_route_reference) return etu_weight(powered_entropy, config_.etu_reference_entropy);
  entropies_.push_back(given_entropy);
  if (entropies_.size() > 2 * kEtuRouteFrames) entropies_.erase(entropies_.begin(), entropies_.end() - kEtuRouteFrames);
  return etu_weight(given_entropy, route_reference_entropy(entropies_));
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
