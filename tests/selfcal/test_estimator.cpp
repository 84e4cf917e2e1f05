// PowerEstimator's sharpness slope (selfcal/estimator.hpp): on evidence whose answer is known by
// construction, it tempers sharper frames only where the sharper frames are the ones the belief
// finds wrong, and never frames as sharp as the route's or flatter.

#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "seqloc/selfcal/estimator.hpp"

namespace seqloc::selfcal {
namespace {

// A frame of 100 cells, its peak one cell and the other 99 four nats under it, against a belief
// whose mass lies all on the peak (`right`) or all on the other cells (the frame is wrong where
// the belief is). P(kappa) = 1 / Z(kappa) and e^{-4 kappa} / Z(kappa), Z(kappa) = 1 + 99 e^{-4 kappa}:
// a right frame favours the sharpest power, a wrong one the flattest.
CalibrationEvidence frame_against_belief(bool right) {
  CalibrationEvidence e;
  e.frame_cells.add(0.0, 1);
  e.frame_cells.add(-4.0, 99);
  e.belief_in_crop.add(right ? 0.0 : -4.0, 1.0);
  e.window_cells = 100;
  return e;
}

// 100 frames, three of every ten (30 in all) wrong and `sharper_wrong` nats sharper than the rest.
PowerEstimator route(double sharper_wrong) {
  PowerEstimator estimator(2.0, 0.0);
  const CalibrationEvidence right = frame_against_belief(true), wrong = frame_against_belief(false);
  for (int t = 0; t < 100; ++t) {
    const bool is_wrong = t % 10 < 3;
    estimator.add(is_wrong ? wrong : right, is_wrong ? sharper_wrong : 0.0);
  }
  return estimator;
}

TEST(PowerEstimator, SharpnessTakesAtMostTwoOctavesOffSharperFramesAndNothingOffTheRest) {
  EXPECT_EQ(PowerEstimator::sharpness_octaves(2.0, 0.5), -1.0);
  EXPECT_EQ(PowerEstimator::sharpness_octaves(4.0, 3.0), -PowerEstimator::kMaxSharpnessOctaves);
  EXPECT_EQ(PowerEstimator::sharpness_octaves(4.0, -1.0), 0.0);  // flatter than the route's frames
  EXPECT_EQ(PowerEstimator::sharpness_octaves(0.0, 5.0), 0.0);
}

TEST(PowerEstimator, TempersSharperFramesWhereTheyAreTheWrongOnes) {
  const PowerEstimator estimator = route(1.0);
  // The wrong frames want the flattest power and the right ones the sharpest: the most a slope
  // may take off the wrong ones, two octaves, is taken.
  EXPECT_EQ(PowerEstimator::sharpness_octaves(estimator.slope(), 1.0), -PowerEstimator::kMaxSharpnessOctaves)
      << "slope " << estimator.slope();
}

TEST(PowerEstimator, KeepsTheSlopeAtZeroWhereTheSharperFramesAreNotTheWrongOnes) {
  // The wrong frames flatter than the rest, or as sharp: no slope helps, none is taken.
  EXPECT_EQ(route(-1.0).slope(), 0.0);
  EXPECT_EQ(route(0.0).slope(), 0.0);
  // The score at slope 0 is the one-parameter estimator's: the same power either way.
  EXPECT_EQ(route(-1.0).power(), route(0.0).power());
}

TEST(PowerEstimator, ResetForgetsTheSlope) {
  PowerEstimator estimator = route(1.0);
  ASSERT_GT(estimator.slope(), 0.0);
  estimator.reset();
  EXPECT_EQ(estimator.slope(), 0.0);
  EXPECT_EQ(estimator.power(), 1.0);
}

}  // namespace
}  // namespace seqloc::selfcal
