#include "seqloc/selfcal/shared_errors.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "seqloc/selfcal/estimator.hpp"

namespace seqloc::selfcal {
namespace {

bool valid(const std::array<double, 2>& e) { return std::isfinite(e[0]) && std::isfinite(e[1]); }

double median(std::vector<double> v) {
  const auto middle = v.begin() + static_cast<std::ptrdiff_t>(v.size() / 2);
  std::nth_element(v.begin(), middle, v.end());
  if (v.size() % 2 == 1) return *middle;
  return 0.5 * (*middle + *std::max_element(v.begin(), middle));
}

}  // namespace

SharedErrors::SharedErrors(int lag, double floor_m) : lag_(lag), floor2_(floor_m * floor_m) {
  if (lag < 2 || lag > 1000) {
    throw EstimatorError("shared errors: the lag must be 2 to 1000 frames, not " + std::to_string(lag));
  }
  if (!(floor_m > 0) || !std::isfinite(floor_m)) {
    throw EstimatorError("shared errors: the floor must be finite and > 0, not " + std::to_string(floor_m));
  }
}

void SharedErrors::reset() {
  errors_.clear();
  pairs_ = 0;
  ratio_ = 1;
  rho_ = 0;
}

void SharedErrors::add(double east_m, double north_m) {
  errors_.push_back({east_m, north_m});
  if (errors_.size() > kPairs + static_cast<std::size_t>(lag_)) errors_.pop_front();
  if (!valid(errors_.back())) return;
  const int lag = lag_for(errors_.size());
  const std::vector<double> ones = squared_steps(1), longs = squared_steps(lag);
  pairs_ = lag == lag_ ? static_cast<int>(longs.size()) : 0;
  const int pairs = static_cast<int>(std::min(ones.size(), longs.size()));
  if (pairs == 0) return;
  // The ratio of the medians, shrunk towards 1 (independent frames) in its log as if `lag` pairs
  // of each had shown no difference: a few pairs cannot make the frames look shared.
  const double log_ratio = std::log((median(longs) + floor2_) / (median(ones) + floor2_));
  ratio_ = std::exp(log_ratio * pairs / (pairs + lag));
  rho_ = correlation_for_ratio(ratio_, lag);
}

int SharedErrors::lag_for(std::size_t frames) const {
  // H once the route has 2H frames, before that the longest lag with as many frames after it as
  // before (at least kShortestLag), so that a route shows shared errors over its first frames.
  return std::clamp(static_cast<int>(std::min(frames / 2, kPairs)), std::min(kShortestLag, lag_), lag_);
}

std::vector<double> SharedErrors::squared_steps(int lag) const {
  const std::size_t n = errors_.size(), h = static_cast<std::size_t>(lag);
  std::vector<double> d2;
  d2.reserve(std::min(n, kPairs));
  for (std::size_t i = std::max(h, n - std::min(n, kPairs)); i < n; ++i) {
    const auto& a = errors_[i];
    const auto& b = errors_[i - h];
    if (valid(a) && valid(b)) d2.push_back((a[0] - b[0]) * (a[0] - b[0]) + (a[1] - b[1]) * (a[1] - b[1]));
  }
  return d2;
}

double SharedErrors::correlation_for_ratio(double r, int lag) {
  if (!(r > 1)) return 0;
  // (1 - rho^H) / (1 - rho) = 1 + rho + ... + rho^(H-1) rises from 1 to H on [0, 1): bisection.
  const auto sum = [lag](double rho) {
    double s = 0, term = 1;
    for (int i = 0; i < lag; ++i, term *= rho) s += term;
    return s;
  };
  double lo = 0, hi = 1;
  for (int i = 0; i < 60; ++i) {
    const double mid = 0.5 * (lo + hi);
    (sum(mid) < r ? lo : hi) = mid;
  }
  return 0.5 * (lo + hi);
}

}  // namespace seqloc::selfcal
