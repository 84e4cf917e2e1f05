// The step's decisions (StepDecisions), which every backend calls: each rule on a case whose
// answer is worked out by hand.

#include <cmath>
#include <limits>
#include <vector>

#include <gtest/gtest.h>

#include "seqloc/filter/seqloc_filter.hpp"
#include "seqloc/filter/step_decisions.hpp"

namespace seqloc::filter {
namespace {

FilterConfig small(int headings = 8) {
  FilterConfig c;
  c.width = c.height = 20;
  c.headings = headings;
  return c;
}

TEST(StepDecisions, ThePowerIsTheRepeatedPassesThenTheEstimateWhileCalibratingElseOne) {
  EXPECT_EQ(StepDecisions::power(FrameWeighting{0.25, 0.5, -1}, true, 2.0), 0.25);
  EXPECT_EQ(StepDecisions::power(std::nullopt, true, 2.0), 2.0);
  EXPECT_EQ(StepDecisions::power(std::nullopt, false, 2.0), 1.0);
}

TEST(StepDecisions, TheHoldRaisesTheBeliefOnceWhenItReleases) {
  StepDecisions d(small());
  EXPECT_EQ(d.hold_ratio(1.0, true), 1.0);
  EXPECT_EQ(d.hold_ratio(0.9, true), 1.0) << "held: the frames went in at the held power";
  EXPECT_DOUBLE_EQ(d.hold_ratio(0.25, false), 0.25 / 0.9) << "released: from the power held until then";
  EXPECT_EQ(d.hold_ratio(0.5, false), 1.0) << "after the release the frames follow the estimate";
  EXPECT_EQ(d.hold_ratio(0.5, true), 1.0) << "the hold is not taken again";
  EXPECT_EQ(d.hold_ratio(2.0, false), 1.0);
  d.reset();
  EXPECT_EQ(d.hold_ratio(1.0, true), 1.0);
  EXPECT_DOUBLE_EQ(d.hold_ratio(4.0, false), 4.0) << "a new route holds again";
}

TEST(StepDecisions, TheBankRaisesTheBeliefWhenItsPowerMovesHalfAnOctave) {
  StepDecisions d(small());
  EXPECT_EQ(d.bank_ratio(1.3), 1.0) << "0.38 octaves";
  EXPECT_DOUBLE_EQ(d.bank_ratio(2.0), 2.0);
  EXPECT_EQ(d.bank_ratio(1.5), 1.0) << "0.42 octaves from the power last applied, 2";
  EXPECT_DOUBLE_EQ(d.bank_ratio(1.0), 0.5);
}

// A frame of the given entropy over 1,000 cells joins the route.
void join(StepDecisions& d, double entropy) {
  PreparedFrame f;
  f.entropy = entropy;
  f.log_cells = std::log(1000.0);
  d.join_route(f);
}

TEST(StepDecisions, EtuWeighsAgainstTheMedianOfTheRoutesLastFrames) {
  FilterConfig c = small();
  StepDecisions d(c);
  // Entropies 0.5, 0.6, 0.7: the third frame's reference is their median 0.6.
  join(d, 0.5);
  EXPECT_EQ(d.etu_weight_of(0.9), 1.0) << "the only frame is its own reference";
  join(d, 0.6);
  EXPECT_EQ(d.etu_weight_of(0.9), 1.0);
  join(d, 0.7);
  EXPECT_NEAR(d.etu_weight_of(0.1), (1 - 0.7) / (1 - 0.6), 1e-12) << "the given entropy, not the powered one";
  for (int i = 0; i < 1000; ++i) join(d, 0.2);
  EXPECT_LE(d.route_entropies().size(), 2 * kEtuRouteFrames);
  join(d, 0.7);
  EXPECT_EQ(d.etu_weight_of(0.7), (1 - 0.7) / (1 - 0.2)) << "the old frames are forgotten";

  c.etu_route_reference = false;
  StepDecisions configured(c);
  join(configured, 0.1);
  EXPECT_NEAR(configured.etu_weight_of(0.95), (1 - 0.95) / (1 - c.etu_reference_entropy), 1e-12)
      << "the configured reference reads the powered frame";
  EXPECT_TRUE(configured.etu_reads_powered_frame());
  c.etu = false;
  StepDecisions without(c);
  join(without, 0.99);
  EXPECT_EQ(without.etu_weight_of(0.99), 1.0);
}

TEST(StepDecisions, AFramesSharpnessIsAgainstTheRoutesFramesBeforeIt) {
  FilterConfig c = small();
  c.self_calibration_sharpness = true;
  StepDecisions d(c);
  // A route's first kSharpnessFrames frames are not read for their sharpness, however sharp.
  ASSERT_EQ(StepDecisions::kSharpnessFrames, 9u) << "the figures below read nine frames";
  for (std::size_t i = 0; i < StepDecisions::kSharpnessFrames; ++i) {
    join(d, i % 2 == 0 ? 0.6 : 0.1);
    EXPECT_EQ(d.sharper_nats(), 0.0) << "frame " << i;
  }
  // Nine frames before it, 0.6 five times and 0.1 four: the median is 0.6.
  join(d, 0.4);
  EXPECT_NEAR(d.sharper_nats(), (0.6 - 0.4) * std::log(1000.0), 1e-12);
  join(d, 0.7);
  // Ten frames before it (0.6 five times, 0.1 four times, 0.4): the median, the upper of the middle
  // two, is 0.6, and the frame 0.1 of log(1,000) nats flatter.
  EXPECT_NEAR(d.sharper_nats(), -0.1 * std::log(1000.0), 1e-12);
  // Before the estimator has found a slope, no frame is tempered for its sharpness.
  EXPECT_EQ(d.sharpness_octaves(true), 0.0);
  EXPECT_EQ(d.sharpness_octaves(false), 0.0);
  // Without the slope nothing reads a frame's sharpness, and none is measured.
  StepDecisions without(small());
  for (std::size_t i = 0; i < StepDecisions::kSharpnessFrames; ++i) join(without, 0.6);
  join(without, 0.4);
  EXPECT_EQ(without.sharper_nats(), 0.0);
}

TEST(StepDecisions, PasIsTheMassWeightedMeanAroundThePeakWithinTheWindow) {
  FilterConfig c = small();
  c.pas_radius = 1;
  // Masses m(u, v) = u + 1 on the cells around (0, 5): the window clips the column u = -1, so the
  // mean is over u = 0, 1 with masses 1 and 2 in each of three rows: u = 2/3, v = 5.
  const PositionMasses masses = [](int u0, int v0, int u1, int v1, std::span<double> out) {
    std::size_t i = 0;
    for (int v = v0; v <= v1; ++v)
      for (int u = u0; u <= u1; ++u) out[i++] = u + 1.0;
  };
  const Pose p = StepDecisions(c).refine(0, 5, 2, c.width, c.height, masses, nullptr);
  EXPECT_NEAR(p.u, 2.0 / 3.0, 1e-12);
  EXPECT_NEAR(p.v, 5.0, 1e-12);
  EXPECT_EQ(p.heading_deg, 2 * 45.0) << "th* without the sub-bin heading";
}

TEST(StepDecisions, TheSubBinHeadingIsTheCircularMeanAroundThePeak) {
  FilterConfig c = small(8);
  c.pas = false;
  c.subbin_heading = true;
  c.subbin_half_width = 1;
  // Bins 7 (315 deg) and 0 (0 deg) equal, bin 1 empty: the mean is 337.5 deg, across north.
  const CellValue value = [](int, int, int k) { return k == 7 || k == 0 ? 1.0 : 0.0; };
  const Pose p = StepDecisions(c).refine(3, 4, 0, c.width, c.height, nullptr, value);
  EXPECT_EQ(p.u, 3);
  EXPECT_EQ(p.v, 4);
  EXPECT_NEAR(p.heading_deg, 337.5, 1e-9);
}

TEST(StepDecisions, RelocalizedWhenTheArgmaxLandsFarFromThePreviousEstimateMoved) {
  FilterConfig c = small();
  c.relocalization_jump_m = 10;
  const StepDecisions d(c);
  const Pose previous{10, 40, 0};      // heading north
  const Odometry five_north{5, 0, 0};  // 10 cells up: expected at (10, 30)
  EXPECT_FALSE(d.relocalized(previous, five_north, {10, 12, 0})) << "9 m from (10, 30)";
  EXPECT_TRUE(d.relocalized(previous, five_north, {10, 8, 0})) << "11 m";
  EXPECT_TRUE(d.relocalized(previous, {}, {10, 18, 0})) << "11 m when it did not move";
}

TEST(StepDecisions, TheEarlyReplayIsDueWhenAKeptFrameWentInHalfAnOctaveAway) {
  const std::vector<double> kept{1.0, 1.0, 0.8};
  EXPECT_FALSE(StepDecisions::replay_due(0.75, kept, 0)) << "0.42 octaves from 1";
  EXPECT_TRUE(StepDecisions::replay_due(0.7, kept, 0)) << "0.51 octaves from 1";
  EXPECT_TRUE(StepDecisions::replay_due(1.45, kept, 0)) << "above as below: 0.54 octaves from 1";
  EXPECT_FALSE(StepDecisions::replay_due(0.7, std::vector<double>{0.7, 0.6}, 0)) << "all within half an octave";
  EXPECT_TRUE(StepDecisions::replay_due(0.25, kept, StepDecisions::kMaxReplays - 1));
  EXPECT_FALSE(StepDecisions::replay_due(0.25, kept, StepDecisions::kMaxReplays)) << "a route's replays are bounded";
}

TEST(StepDecisions, ThePoweredPeakIsTheTemperedFramesPeak) {
  // A frame raised to k and renormalized (temper_frame, which writes it) has the peak
  // powered_peak_log_prob computes without writing it.
  std::vector<float> values(6 * 5 * 8);
  for (std::size_t i = 0; i < values.size(); ++i)
    values[i] = static_cast<float>(std::sin(0.7 * static_cast<double>(i)) * 3.0);
  values[17] = -std::numeric_limits<float>::infinity();  // a zero
  const PreparedFrame frame =
      prepare_frame({values.data(), VolumeType::float32, VolumeValues::log_prob, 6, 5, 8, 0.5}, 8);
  for (const double k : {0.25, 1.0, 3.0}) {
    EXPECT_NEAR(powered_peak_log_prob(frame, k), temper_frame(frame, k).max_log_prob, 1e-5) << "k = " << k;
    EXPECT_EQ(powered_peak_log_prob(frame, k, 3), powered_peak_log_prob(frame, k, 1)) << "any number of threads";
  }
}

// A frame whose only peak is at crop cell (v, u), heading bin 0, on a 9 x 9 crop of 8 bins.
PreparedFrame peak_at(int v, int u) {
  std::vector<float> values(9 * 9 * 8, -30.0f);
  values[(static_cast<std::size_t>(v) * 9 + static_cast<std::size_t>(u)) * 8] = 0.0f;
  return prepare_frame({values.data(), VolumeType::float32, VolumeValues::log_prob, 9, 9, 8, 0.5}, 8);
}

// A vehicle standing still heading north, its estimate at the crop's centre (10, 10), no peak far
// enough to count as another place: the config, and a frame whose peak is at crop row 4, column u.
FilterConfig standing() {
  FilterConfig c = small();
  c.relocalization_jump_m = 100;
  return c;
}
void observe_standing(StepDecisions& d, int u) {
  d.track({}, Pose{10, 10, 0});
  d.observe(peak_at(4, u), CropPose{10, 10, 0});
}

TEST(StepDecisions, FramesThatShareTheirErrorsAreFlattenedAndNotSharpened) {
  // The vehicle stands still heading north with its estimate at the crop's centre (10, 10). Route
  // A's peaks drift one cell a frame along u and back every 16 frames (consecutive peaks 0.5 m
  // apart, peaks 10 frames apart 1 to 4 m apart: shared errors); route B's alternate between two
  // cells 2 m apart (2 m at odd lags, none at even ones: nothing shared).
  FilterConfig c = standing();
  StepDecisions shared(c), independent(c);
  for (int t = 0; t < 40; ++t) {
    observe_standing(shared, t % 16 < 8 ? t % 16 : 16 - t % 16);
    observe_standing(independent, t % 2 == 0 ? 0 : 4);
  }
  EXPECT_GT(shared.shared_errors().correlation(), 0.5);
  EXPECT_LT(shared.shared_factor(), 0.5);
  EXPECT_EQ(shared.shared_cap(4.0), 1.0) << "the estimator may not sharpen shared frames";
  EXPECT_EQ(shared.shared_cap(0.25), 0.25) << "it may flatten them";
  EXPECT_DOUBLE_EQ(shared.frame_power(std::nullopt, true, 4.0), shared.shared_factor());
  EXPECT_EQ(shared.frame_power(FrameWeighting{0.3, 1, 0}, true, 4.0), 0.3) << "a repeated pass's power stands";
  EXPECT_EQ(shared.frame_power(std::nullopt, false, 4.0), 1.0);

  EXPECT_EQ(independent.shared_errors().correlation(), 0.0) << "lag 10 is even: the same 2 m at both lags";
  EXPECT_EQ(independent.shared_factor(), 1.0);
  EXPECT_EQ(independent.shared_cap(4.0), 4.0) << "independent frames may be sharpened";

  c.self_calibration_shared_lag = 0;
  StepDecisions off(c);
  observe_standing(off, 0);
  EXPECT_EQ(off.shared_factor(), 1.0);
  EXPECT_EQ(off.shared_cap(4.0), 4.0);
}

TEST(StepDecisions, TheEstimatorSharpensOnlyAfterLagPairsHaveShownIndependentFrames) {
  const FilterConfig c = standing();
  StepDecisions d(c);
  for (int t = 0; t < 2 * c.self_calibration_shared_lag; ++t) {
    EXPECT_EQ(d.shared_cap(4.0), 1.0) << "frame " << t << ": " << d.shared_errors().pairs() << " pairs";
    observe_standing(d, t % 2 == 0 ? 0 : 4);
  }
  EXPECT_EQ(d.shared_errors().pairs(), c.self_calibration_shared_lag);
  EXPECT_EQ(d.shared_cap(4.0), 4.0);
  EXPECT_EQ(d.shared_cap(2.5), 2.5);
  EXPECT_EQ(d.shared_cap(13.0), 4.0) << "two octaves at most";
  EXPECT_EQ(d.shared_cap(0.1), 0.1);
}

TEST(StepDecisions, APeakFartherThanARelocalizationsJumpIsLeftOut) {
  FilterConfig c = small();
  c.relocalization_jump_m = 2;
  c.self_calibration_shared_lag = 2;
  StepDecisions d(c);
  const CropPose crop{10, 10, 0};
  // The estimate heads north and moves 1 m (2 cells) a frame: each prediction is 2 cells north of
  // the estimate it moves. Peaks at the crop's centre (10, 10) are where the first three are
  // predicted; the fourth prediction is (10, 12), and a peak at crop row 0, window (10, 6), lies
  // 3 m from it.
  Pose estimate{10, 12, 0};
  const Odometry step{1, 0, 0};
  d.track(step, estimate);
  d.observe(peak_at(4, 4), crop);
  d.track(step, estimate);
  d.observe(peak_at(4, 4), crop);
  d.track(step, estimate);
  d.observe(peak_at(4, 4), crop);
  EXPECT_EQ(d.shared_errors().pairs(), 1);
  d.track(step, Pose{10, 14, 0});  // predicted at (10, 12): the peak at crop row 0 is (10, 6), 3 m off
  d.observe(peak_at(0, 4), crop);
  EXPECT_EQ(d.shared_errors().pairs(), 1) << "left out: no pair";
  d.reset();
  EXPECT_EQ(d.shared_errors().pairs(), 0);
}

TEST(StepDecisions, TheBeliefIsRaisedWhenTheSharedFactorMovesHalfAnOctave) {
  StepDecisions d(standing());
  double product = 1;
  for (int t = 0; t < 40; ++t) {
    observe_standing(d, t % 16 < 8 ? t % 16 : 16 - t % 16);
    const double ratio = d.belief_ratio(1.0, true);
    EXPECT_TRUE(ratio == 1.0 || std::abs(std::log2(ratio)) >= 0.5) << t << ": " << ratio;
    product *= ratio;
  }
  // The belief's frames went in at the last factor it was raised to: within half an octave of
  // the factor now.
  EXPECT_LT(std::abs(std::log2(product / d.shared_factor())), 0.5);
  EXPECT_LT(product, 0.75);
}

TEST(StepDecisions, TheSharedFactorFallsAtOnceAndRisesAQuarterOctaveAFrameAtMost) {
  // Peaks held three frames at each of five cells (shared errors) for 20 frames, then jumping
  // among them (7 t mod 5: nothing shared). The estimate's factor falls to 1/16 at the fourth
  // frame and climbs back to 1 within a few frames once the jumps come; the frames go in at a
  // factor that follows it down at once and up by a quarter octave a frame.
  StepDecisions d(standing());
  double used = 1;
  int falls = 0, held_back = 0;
  for (int t = 0; t < 60; ++t) {
    observe_standing(d, t < 20 ? (t / 3) % 5 : (t * 7) % 5);
    const double estimate = d.shared_errors().factor(), rise = used * std::exp2(0.25);
    falls += estimate < used / std::exp2(0.25);
    held_back += estimate > rise;
    EXPECT_DOUBLE_EQ(d.shared_factor(), std::min(estimate, rise)) << "frame " << t;
    used = d.shared_factor();
  }
  EXPECT_GE(falls, 1);
  EXPECT_GE(held_back, 5) << "the estimate rose faster than a quarter octave a frame on several frames";
  EXPECT_EQ(d.shared_factor(), 1.0) << "independent frames go in as given again";
}

}  // namespace
}  // namespace seqloc::filter
