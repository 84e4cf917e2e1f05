// Angle wrapping against the definition, including the values on the edges.

#include <gtest/gtest.h>

#include <cmath>

#include "seqloc/core/angles.hpp"

namespace seqloc::core {
namespace {

TEST(Angles, Wrap360IsTheRemainderIn0To360) {
  EXPECT_EQ(wrap360(0), 0);
  EXPECT_EQ(wrap360(360), 0);
  EXPECT_EQ(wrap360(-90), 270);
  EXPECT_EQ(wrap360(725), 5);
  EXPECT_EQ(wrap360(-720), 0);
  for (double d = -1000; d < 1000; d += 7.25) {
    const double w = wrap360(d);
    EXPECT_GE(w, 0) << d;
    EXPECT_LT(w, 360) << d;
    const double turns = (d - w) / 360;
    EXPECT_NEAR(turns, std::round(turns), 1e-12) << d;
  }
}

TEST(Angles, Wrap180IsTheTurnIn180To180) {
  EXPECT_EQ(wrap180(180), -180);
  EXPECT_EQ(wrap180(-180), -180);
  EXPECT_EQ(wrap180(190), -170);
  EXPECT_EQ(wrap180(-190), 170);
  EXPECT_EQ(wrap180(359), -1);
}

TEST(Angles, HeadingDifferenceIsTheSmallerAngle) {
  EXPECT_EQ(heading_difference_deg(350, 10), 20);
  EXPECT_EQ(heading_difference_deg(10, 350), 20);
  EXPECT_EQ(heading_difference_deg(0, 180), 180);
  EXPECT_EQ(heading_difference_deg(720 + 5, 0), 5);
  EXPECT_EQ(heading_difference_deg(-30, 30), 60);
}

}  // namespace
}  // namespace seqloc::core
