#include "seqloc/selfcal/shared_errors.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "seqloc/selfcal/estimator.hpp"

namespace seqloc::selfcal {
namespace {

double median(const std::deque<double>& values) {
  std::vector<double> v(values.begin(), values.end());
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
  recent_.clear();
  short_.clear();
  long_.clear();
  pairs_ = 0;
  ratio_ = 1;
  rho_ = 0;
}

void SharedErrors::add(double east_m, double north_m) {
  recent_.push_back({east_m, north_m});
  if (recent_.size() > static_cast<std::size_t>(lag_) + 1) recent_.pop_front();
  if (recent_.size() <= static_cast<std::size_t>(lag_)) return;
  const auto valid = [](const std::array<double, 2>& e) { return std::isfinite(e[0]) && std::isfinite(e[1]); };
  if (!valid(recent_.back())) return;
  const auto squared_distance = [](const std::array<double, 2>& a, const std::array<double, 2>& b) {
    const double dx = a[0] - b[0], dy = a[1] - b[1];
    return dx * dx + dy * dy;
  };
  // The newest frame against the one before and the one H before, each pair where both frames
  // were taken; the last kPairs pairs of each lag are kept.
  const auto keep = [](std::deque<double>& pairs, double d2) {
    pairs.push_back(d2);
    if (pairs.size() > kPairs) pairs.pop_front();
  };
  if (valid(recent_[recent_.size() - 2])) keep(short_, squared_distance(recent_.back(), recent_[recent_.size() - 2]));
  if (valid(recent_.front())) keep(long_, squared_distance(recent_.back(), recent_.front()));
  pairs_ = static_cast<int>(std::min(short_.size(), long_.size()));
  if (pairs_ == 0) return;
  // The ratio of the medians, shrunk towards 1 (independent frames) in its log as if `lag` pairs
  // of each had shown no difference: a few pairs cannot make the frames look shared.
  const double log_ratio = std::log((median(long_) + floor2_) / (median(short_) + floor2_));
  ratio_ = std::exp(log_ratio * pairs_ / (pairs_ + lag_));
  rho_ = correlation_for_ratio(ratio_, lag_);
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
