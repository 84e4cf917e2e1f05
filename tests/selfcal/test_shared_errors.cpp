// SharedErrors (selfcal/shared_errors.hpp): the correlation of frames' errors read from a variogram
// of their peaks, checked against processes whose correlation is known by construction.

#include <cmath>
#include <limits>
#include <random>

#include <gtest/gtest.h>

#include "seqloc/selfcal/estimator.hpp"
#include "seqloc/selfcal/shared_errors.hpp"

namespace seqloc::selfcal {
namespace {

// The errors of `frames` frames along a fixed direction: an AR(1) process of correlation rho and
// standard deviation sigma_m, started in its stationary law.
SharedErrors read(double rho, int frames, unsigned seed, double sigma_m = 4, int lag = 10) {
  std::mt19937 rng(seed);
  std::normal_distribution<double> normal(0, 1);
  const double fresh = std::sqrt(1 - rho * rho), direction = 0.7;
  SharedErrors shared(lag);
  double e = normal(rng);
  for (int t = 0; t < frames; ++t) {
    if (t > 0) e = rho * e + fresh * normal(rng);
    shared.add(sigma_m * e * std::cos(direction), sigma_m * e * std::sin(direction));
  }
  return shared;
}

TEST(SharedErrors, TheCorrelationSolvesTheGeometricSum) {
  for (const double rho : {0.1, 0.5, 0.8, 0.95, 0.99}) {
    double r = 0;
    for (int i = 0; i < 10; ++i) r += std::pow(rho, i);
    EXPECT_NEAR(SharedErrors::correlation_for_ratio(r, 10), rho, 1e-12) << rho;
  }
  EXPECT_EQ(SharedErrors::correlation_for_ratio(1.0, 10), 0.0);
  EXPECT_EQ(SharedErrors::correlation_for_ratio(0.5, 10), 0.0) << "a ratio under 1: independent";
  EXPECT_EQ(SharedErrors::correlation_for_ratio(std::numeric_limits<double>::quiet_NaN(), 10), 0.0);
}

TEST(SharedErrors, ReadsTheVariogramOfAnAr1Process) {
  // gamma(10) / gamma(1) = (1 - rho^10) / (1 - rho): 1.0, 2.0, 4.46 and 8.03 for the rho below.
  // Each route's ratio is a median over its last 1,024 pairs, whose neighbours share most of
  // their frames (more so the larger rho: at 0.95 they amount to some 50 independent pairs, a
  // standard error near 0.15 in the log ratio): over eight routes of 4,000 frames the mean of the
  // log ratio is within 0.05 of the truth (the shrinkage towards 1 takes 1 % of it), and each
  // route's within 0.4.
  for (const double rho : {0.0, 0.5, 0.8, 0.95}) {
    const double expected = std::log((1 - std::pow(rho, 10)) / (1 - rho));
    double mean = 0;
    for (unsigned seed = 1; seed <= 8; ++seed) {
      const double log_ratio = std::log(read(rho, 4000, seed).ratio());
      EXPECT_NEAR(log_ratio, expected, 0.4) << rho << " " << seed;
      mean += log_ratio / 8;
    }
    EXPECT_NEAR(mean, expected, 0.05) << rho;
  }
  // Independent frames: the ratio's noise reads as a little correlation, which the steep inverse
  // near 1 turns into a factor of 0.65 to 1 on these routes (0.88 on average).
  double mean_factor = 0;
  for (unsigned seed = 1; seed <= 8; ++seed) {
    const double factor = read(0.0, 4000, seed).factor();
    EXPECT_GT(factor, 0.6) << seed;
    mean_factor += factor / 8;
  }
  EXPECT_GT(mean_factor, 0.8);
}

TEST(SharedErrors, TheFactorCountsTheFramesAsIndependentLooks) {
  const SharedErrors shared = read(0.8, 4000, 3);
  const double rho = shared.correlation();
  EXPECT_DOUBLE_EQ(shared.factor(), (1 - rho) / (1 + rho));
  EXPECT_EQ(read(0.999, 4000, 3).factor(), SharedErrors::kMinFactor) << "never under one look in 16";
}

TEST(SharedErrors, ReadsShortLagsOverTheFirstFramesAndLittleFromAFewPairs) {
  SharedErrors shared(10);
  const double eps2 = 0.05 * 0.05;
  shared.add(0, 0);  // a steady drift of 1 m a frame: fully shared
  shared.add(1, 0);
  shared.add(2, 0);
  EXPECT_EQ(shared.correlation(), 0.0) << "no pair at lag 3 yet";
  EXPECT_EQ(shared.factor(), 1.0);
  shared.add(3, 0);
  // Four frames: lag 3 (one pair, |d|^2 = 9) against lag 1 (median 1), shrunk by 1 / (1 + 3).
  EXPECT_EQ(shared.lag_read(), 3);
  EXPECT_EQ(shared.pairs(), 0) << "pairs of the full lag only";
  EXPECT_NEAR(std::log(shared.ratio()), (std::log(9 + eps2) - std::log(1 + eps2)) / 4, 1e-12);
  const double rho = shared.correlation();
  EXPECT_NEAR(1 + rho + rho * rho, shared.ratio(), 1e-9) << "(1 - rho^3) / (1 - rho)";
  EXPECT_LT(shared.factor(), 1.0);
  for (int t = 4; t <= 12; ++t) shared.add(t, 0);
  EXPECT_EQ(shared.lag_read(), 6) << "13 frames: the longest lag with as many frames after it as before";
  for (int t = 13; t <= 19; ++t) shared.add(t, 0);
  EXPECT_EQ(shared.lag_read(), 10);
  EXPECT_EQ(shared.pairs(), 10);
  // Log ratio log(100 + eps^2) - log(1 + eps^2), shrunk by 10 / (10 + 10).
  EXPECT_NEAR(std::log(shared.ratio()), (std::log(100 + eps2) - std::log(1 + eps2)) / 2, 1e-12);
  EXPECT_EQ(shared.factor(), SharedErrors::kMinFactor) << "a drift that never changes: shared";
  shared.reset();
  EXPECT_EQ(shared.pairs(), 0);
  EXPECT_EQ(shared.ratio(), 1.0);
  EXPECT_EQ(shared.factor(), 1.0);
}

TEST(SharedErrors, FramesLeftOutMakeNoPair) {
  SharedErrors shared(2);
  const double nan = std::numeric_limits<double>::quiet_NaN();
  shared.add(0, 0);
  shared.add(1, 0);
  EXPECT_EQ(shared.pairs(), 0);
  shared.add(nan, 0);  // left out: no pair with it
  EXPECT_EQ(shared.pairs(), 0);
  shared.add(3, 0);  // lag 2 against frame 1; lag 1 against the frame left out
  EXPECT_EQ(shared.pairs(), 1);
  const double after_three = shared.ratio();
  // Pairs (1, 0) at lag 1 and (3, 1) at lag 2: log(4 + eps^2) - log(1 + eps^2), shrunk by 1 / 3.
  const double eps2 = 0.05 * 0.05;
  EXPECT_NEAR(std::log(after_three), (std::log(4 + eps2) - std::log(1 + eps2)) / 3, 1e-12);
  shared.add(4, 0);  // lag 1 against frame 3; lag 2 against the frame left out
  EXPECT_EQ(shared.pairs(), 1);
  EXPECT_TRUE(std::isfinite(shared.ratio()));
}

TEST(SharedErrors, AFewFramesAtAnotherPlaceDoNotMakeIndependentFramesLookShared) {
  std::mt19937 rng(5);
  std::normal_distribution<double> normal(0, 2);
  std::uniform_real_distribution<double> unit(0, 1);
  SharedErrors shared(10);
  for (int t = 0; t < 2000; ++t) {
    const bool elsewhere = unit(rng) < 0.05;
    shared.add(normal(rng) + (elsewhere ? 30 : 0), normal(rng));
  }
  EXPECT_LT(shared.correlation(), 0.1);
}

TEST(SharedErrors, RefusesALagOrFloorOutOfRange) {
  EXPECT_THROW(SharedErrors(1), EstimatorError);
  EXPECT_THROW(SharedErrors(1001), EstimatorError);
  EXPECT_THROW(SharedErrors(10, 0.0), EstimatorError);
  EXPECT_THROW(SharedErrors(10, std::numeric_limits<double>::infinity()), EstimatorError);
}

}  // namespace
}  // namespace seqloc::selfcal
