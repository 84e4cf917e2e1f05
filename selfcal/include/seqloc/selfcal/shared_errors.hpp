#pragma once
// How much consecutive frames share their errors, from the frames alone (no ground truth).
//
// A backbone's frames of overlapping scenes make the same mistake for a while: their errors are
// correlated along the route. The recursion counts each frame as an independent look, so n frames
// whose errors follow an AR(1) process of correlation rho are worth n (1 - rho) / (1 + rho)
// independent ones (the variance of their mean is (1 + rho) / (1 - rho) times that of independent
// frames'). Raising every frame to the power c = (1 - rho) / (1 + rho) as well makes the belief as
// sure as those frames warrant, and lets the motion average the shared errors over the route
// rather than follow them. A one-step criterion cannot see rho: frames that share their errors
// agree with each other.
//
// rho is read from a variogram of the frames' peaks. Let z_t be frame t's peak (the single-frame
// pose) and P_t a dead-reckoned point (the odometry applied from an arbitrary start along the
// filter's heading); e_t = z_t - P_t is the frame's error up to a constant while the odometry
// holds. For errors of variance s^2 and correlation rho^h at lag h,
//
//   gamma(h) = E |e_t - e_{t-h}|^2 / 2 = s^2 (1 - rho^h),   gamma(H) / gamma(1) = (1 - rho^H) / (1 - rho),
//
// which is 1 for independent errors and H for errors that never change. The ratio is taken of
// medians of |d|^2 over the route's last kPairs pairs of each lag: a frame that is wrong by 20 m
// counts as one above the median, not as a hundred frames wrong by 2 m, and for Gaussian errors
// the median's shape constant cancels (a mean of log |d|^2 would be as robust, but a floor under
// it, needed where peaks on a grid coincide, biases it by the square root of floor over
// variance). Then rho solves the equation above, and c follows. A route's first 2H frames are read
// at the longest lag h < H with as many frames after it as before, at least 3 (gamma(h) / gamma(1) =
// (1 - rho^h) / (1 - rho)): the frames that would lock a belief onto a shared error are its first,
// and a lag of 3 already tells errors that persist from errors that do not.

#include <algorithm>
#include <array>
#include <cstddef>
#include <deque>
#include <vector>

namespace seqloc::selfcal {

class SharedErrors {
 public:
  /// `lag` H >= 2: the longest lag compared (frames); `floor_m` eps > 0: added (squared) to both
  /// medians, so that peaks that coincide at both lags read as independent, and at lag 1 alone
  /// as shared.
  explicit SharedErrors(int lag = 10, double floor_m = 0.05);

  /// Adds frame t's error up to a constant, e_t = z_t - P_t (metres, on any fixed axes); a value
  /// that is not finite marks a frame left out (a peak at another place), and no pair is taken
  /// with it.
  void add(double east_m, double north_m);
  /// rho from the frames so far: 0 until a pair of each lag read has come.
  [[nodiscard]] double correlation() const { return rho_; }
  /// c = (1 - rho) / (1 + rho) in (0, 1]: the power that counts the frames as independent looks.
  [[nodiscard]] double factor() const { return std::max((1 - rho_) / (1 + rho_), kMinFactor); }
  static constexpr double kMinFactor = 1.0 / 16;
  /// The shortest lag read over a route's first frames (lag 2 read on the ridge routes' first frames
  /// swung the factor between 1/16 and 1 from one frame to the next).
  static constexpr int kShortestLag = 3;
  /// The frames the pairs of each lag are taken among (the route's last ones).
  static constexpr std::size_t kPairs = 1024;
  /// gamma(h) / gamma(1) from the frames so far, h the lag read (1 until a pair of each has come).
  [[nodiscard]] double ratio() const { return ratio_; }
  /// The lag h the ratio compares with lag 1: the longest with as many frames after it as before,
  /// from kShortestLag (or H if shorter) up to H, reached once the route has 2H frames.
  [[nodiscard]] int lag_read() const { return lag_for(errors_.size()); }
  /// Pairs of the full lag H the ratio was taken over (0 while a shorter lag is read).
  [[nodiscard]] int pairs() const { return pairs_; }
  void reset();

  /// rho in [0, 1) with (1 - rho^h) / (1 - rho) = r (0 for r <= 1; near 1 for r near h).
  [[nodiscard]] static double correlation_for_ratio(double r, int lag);

 private:
  /// The lag read among `frames` kept errors (lag_read()).
  [[nodiscard]] int lag_for(std::size_t frames) const;
  /// |d|^2 of the pairs (t, t - lag) whose frames are both among the last kPairs and were taken.
  [[nodiscard]] std::vector<double> squared_steps(int lag) const;

  int lag_;
  double floor2_;
  std::deque<std::array<double, 2>> errors_;  ///< the last kPairs + H errors, newest last
  int pairs_ = 0;
  double ratio_ = 1, rho_ = 0;
};

}  // namespace seqloc::selfcal
