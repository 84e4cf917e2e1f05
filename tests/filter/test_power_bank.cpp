// Self-calibration's bank of coarse filters (power_bank.hpp): the power it settles on for volumes
// whose miscalibration is known, causality, and the same powers for any number of threads.

#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "filter/ridge_routes.hpp"
#include "seqloc/filter/power_bank.hpp"
#include "seqloc/filter/seqloc_filter.hpp"

namespace seqloc::filter {
namespace {

using test::RidgeKind;
using test::RidgeRoute;

FilterConfig bank_config() {
  FilterConfig c = RidgeRoute::config();
  c.self_calibration_bank = true;
  return c;
}

// Calibrated frames with independent errors: a round blob of 3 m around a peak drawn from N(truth,
// 3 m), each frame raised to k, the window recentred as the vehicle drives.
RidgeKind blob(double k) { return {.sharpen = k, .rho = 0, .along_m = 3, .across_m = 3, .backwards = 0}; }

// Runs a route; returns each frame's result, and the bank's power after the last frame in `power`.
std::vector<FrameResult> run(RidgeRoute route, const FilterConfig& c, int frames, double* power = nullptr) {
  SeqLocFilter filter(c);
  filter.reset_uniform();
  const auto road = RidgeRoute::road();
  std::vector<FrameResult> results;
  for (int t = 0; t < frames; ++t) {
    const auto f = route.next();
    if (f.recentre_dv != 0) filter.recentre(0, f.recentre_dv);
    results.push_back(filter.step(prepare_frame(RidgeRoute::view(f), c.headings), f.crop, f.odometry, road));
  }
  if (power != nullptr) *power = filter.power_bank()->power();
  return results;
}

class BankRecovers : public ::testing::TestWithParam<double> {};

TEST_P(BankRecovers, APowerWithinAnOctaveOfTheOneThatUndoesAKnownSharpening) {
  // The members span 2^-4 .. 2^2; volumes sharpened by k call for 1 / k. After 60 frames the
  // bank's power times k is within an octave of 1 (geometric mean of three routes): a bank that
  // did not read the frames (power 1) misses it for k = 0.25, 4 and 8, one that read them the
  // wrong way round for every k but 1.
  const double k = GetParam();
  double log2_sum = 0;
  for (const unsigned seed : {11u, 12u, 13u}) {
    double power = 0;
    run(RidgeRoute(blob(k), seed), bank_config(), 60, &power);
    log2_sum += std::log2(power * k);
  }
  EXPECT_LE(std::abs(log2_sum / 3), 1.0) << "k = " << k << ": power times k is 2^" << log2_sum / 3;
}

INSTANTIATE_TEST_SUITE_P(PowerBank, BankRecovers, ::testing::Values(0.25, 1.0, 4.0, 8.0),
                         [](const auto& p) { return "k" + std::to_string(static_cast<int>(p.param * 100)); });

TEST(PowerBank, IsCausal) {
  // Frames after t change nothing at t: the same route up to frame 14, frames of another kind after.
  const FilterConfig c = bank_config();
  const auto a = run(RidgeRoute(test::sharp_shared(), 7), c, 15);
  RidgeRoute same(test::sharp_shared(), 7);
  SeqLocFilter filter(c);
  filter.reset_uniform();
  const auto road = RidgeRoute::road();
  for (int t = 0; t < 25; ++t) {
    auto f = same.next();
    if (t >= 15) {
      for (auto& x : f.values) x = -0.5f * x;  // a different frame from here on
    }
    if (f.recentre_dv != 0) filter.recentre(0, f.recentre_dv);
    const auto r = filter.step(prepare_frame(RidgeRoute::view(f), c.headings), f.crop, f.odometry, road);
    if (t < 15) {
      EXPECT_EQ(r.volume_power, a[static_cast<std::size_t>(t)].volume_power) << "frame " << t;
      EXPECT_EQ(r.pose.u, a[static_cast<std::size_t>(t)].pose.u) << "frame " << t;
      EXPECT_EQ(r.pose.v, a[static_cast<std::size_t>(t)].pose.v) << "frame " << t;
    }
  }
}

TEST(PowerBank, ThePowersAreTheSameForAnyNumberOfThreads) {
  // The sums are made per heading bin and added in bin order.
  FilterConfig c = bank_config();
  const auto a = run(RidgeRoute(blob(4), 5), c, 20);
  c.threads = 3;
  const auto b = run(RidgeRoute(blob(4), 5), c, 20);
  for (std::size_t t = 0; t < a.size(); ++t) EXPECT_EQ(a[t].volume_power, b[t].volume_power) << "frame " << t;
  EXPECT_NE(a.back().volume_power, 1.0) << "volumes four times too sharp move the power";
}

TEST(PowerBank, PoolsTheBeliefAndFollowsTheWindow) {
  // A Gaussian start pooled onto the coarse window keeps its mass where the window cells had it,
  // and a window move of whole coarse cells moves every member by as many.
  FilterConfig c = bank_config();
  c.width = c.height = 64;
  PowerBank bank(c);
  BeliefVolume belief(c.width, c.height, c.headings);
  belief.set_gaussian(20, 40, 2);
  bank.reset(belief);
  auto peak = [](const BeliefVolume& b) {
    int best = 0;
    const auto m = b.position_marginal();
    for (std::size_t i = 0; i < m.size(); ++i)
      if (m[i] > m[static_cast<std::size_t>(best)]) best = static_cast<int>(i);
    return std::pair{best % b.width(), best / b.width()};
  };
  EXPECT_NEAR(bank.member(0).total_probability(), 1.0, 1e-5);
  EXPECT_EQ(peak(bank.member(0)), (std::pair{10, 20}));
  bank.recentre(4, -6);  // the window moves 4 cells east, 6 north: the peak 2 coarse cells west, 3 south
  for (std::size_t i = 0; i < bank.powers().size(); ++i) EXPECT_EQ(peak(bank.member(i)), (std::pair{8, 23})) << i;
  // One window cell east (the peak at window cell 15): the coarse cells now pair window cells 15
  // and 16, the peak's in coarse cell 7; one more (window cell 14) pairs 14 and 15, still 7.
  bank.recentre(1, 0);
  EXPECT_EQ(peak(bank.member(0)), (std::pair{7, 23}));
  bank.recentre(1, 0);
  EXPECT_EQ(peak(bank.member(0)), (std::pair{7, 23}));
  EXPECT_NEAR(bank.member(0).total_probability(), 1.0, 1e-5) << "moves this small lose no mass";
}

}  // namespace
}  // namespace seqloc::filter
