#include <algorithm>
#include <cmath>
#include <vector>

#include <gtest/gtest.h>

#include "seqloc/pipeline/volume_shape.hpp"

namespace seqloc::pipeline::volume_shape_tests {
namespace {

// A prob volume (H, W, N): a Gaussian in the plane, sigma_major along the axis at `axis_deg`
// (clockwise from north), mixed with a uniform floor of share `floor`.
filter::PreparedFrame gaussian(double axis_deg, double sigma_major_m, double sigma_minor_m, double floor) {
  constexpr int kSide = 129, kBins = 4;
  constexpr double kCell = 0.5;
  std::vector<float> values(static_cast<std::size_t>(kSide * kSide * kBins));
  const double a = axis_deg * M_PI / 180.0;
  const double ax_e = std::sin(a), ax_n = std::cos(a);  // the major axis, (east, north)
  double sum = 0;
  std::vector<double> g(static_cast<std::size_t>(kSide * kSide));
  for (int v = 0; v < kSide; ++v)
    for (int u = 0; u < kSide; ++u) {
      const double e = (u - 64) * kCell, n = -(v - 64) * kCell;
      const double along = e * ax_e + n * ax_n, across = -e * ax_n + n * ax_e;
      const double x = std::exp(-0.5 * (along * along / (sigma_major_m * sigma_major_m) +
                                        across * across / (sigma_minor_m * sigma_minor_m)));
      g[static_cast<std::size_t>(v * kSide + u)] = x;
      sum += x;
    }
  for (std::size_t i = 0; i < g.size(); ++i) {
    const double p = (1 - floor) * g[i] / sum + floor / static_cast<double>(g.size());
    for (int k = 0; k < kBins; ++k) values[i * kBins + static_cast<std::size_t>(k)] = static_cast<float>(p / kBins);
  }
  const filter::FrameVolume view{values.data(), filter::VolumeType::float32, filter::VolumeValues::prob, kSide, kSide, kBins, kCell};
  return filter::prepare_frame(view, kBins);
}

TEST(VolumeShape, ARidgeIsLongAlongItsAxisAndAPeakIsRound) {
  // A ridge 8 m x 1 m along heading 30 degrees, under half its mass of floor.
  const auto ridge = gaussian(30, 8, 1, 0.5);
  const auto along = volume_shape(ridge, 30), across = volume_shape(ridge, 120), reversed = volume_shape(ridge, 210);
  EXPECT_NEAR(along.elongation, 8.0, 0.4);
  EXPECT_NEAR(along.major_sigma_m, 8.0, 0.4);
  EXPECT_NEAR(along.minor_sigma_m, 1.0, 0.1);
  EXPECT_NEAR(along.axis_to_heading_deg, 0.0, 0.5);
  EXPECT_NEAR(across.axis_to_heading_deg, 90.0, 0.5);
  EXPECT_NEAR(reversed.axis_to_heading_deg, 0.0, 0.5) << "an axis has no direction";
  const auto peak = volume_shape(gaussian(30, 2, 2, 0.5), 0);
  EXPECT_NEAR(peak.elongation, 1.0, 0.05);
  EXPECT_NEAR(peak.major_sigma_m, 2.0, 0.1);
  // North-south ridge, heading east: across.
  EXPECT_NEAR(volume_shape(gaussian(0, 6, 1.5, 0.0), 90).axis_to_heading_deg, 90.0, 0.5);
}

// Each volume cell's mass lands on the window cell its centre falls in, worked out here by hand for
// a crop as given and one turned a quarter clockwise (north-up crop whose north is the window's
// east): cell (v, u) of the 129 x 129 frame at window (cu + (u - 64), cv + (v - 64)), and turned,
// at (cu - (v - 64), cv + (u - 64)); cells falling outside the window are dropped.
TEST(WindowMarginal, PlacesEachCellWhereItsCentreFalls) {
  const auto frame = gaussian(30, 8, 1, 0.2);
  const std::vector<double> own = position_marginal(frame);
  constexpr int kW = 200, kH = 180, kCu = 100, kCv = 90;
  const auto as_given = window_marginal(frame, {kCu, kCv, 0}, kW, kH);
  const auto turned = window_marginal(frame, {kCu, kCv, 90}, kW, kH);
  ASSERT_EQ(as_given.size(), static_cast<std::size_t>(kW * kH));
  for (int v = 0; v < frame.height; ++v) {
    for (int u = 0; u < frame.width; ++u) {
      const double mass = own[static_cast<std::size_t>(v * frame.width + u)];
      const int au = kCu + (u - 64), av = kCv + (v - 64), tu = kCu - (v - 64), tv = kCv + (u - 64);
      ASSERT_NEAR(as_given[static_cast<std::size_t>(av * kW + au)], mass, 1e-7 * std::max(1.0, mass)) << v << "," << u;
      ASSERT_NEAR(turned[static_cast<std::size_t>(tv * kW + tu)], mass, 1e-7 * std::max(1.0, mass)) << v << "," << u;
    }
  }
  // Near the window's corner: what falls outside is dropped, nothing else.
  const auto corner = window_marginal(frame, {10, 20, 0}, kW, kH);
  double inside = 0, placed = 0;
  for (int v = 0; v < frame.height; ++v) {
    for (int u = 0; u < frame.width; ++u) {
      if (10 + (u - 64) >= 0 && 20 + (v - 64) >= 0) inside += own[static_cast<std::size_t>(v * frame.width + u)];
    }
  }
  for (const float x : corner) placed += x;
  EXPECT_NEAR(placed, inside, 1e-5);
  EXPECT_LT(inside, 0.9);  // a good part of the frame did fall outside
}

}  // namespace
}  // namespace seqloc::pipeline::volume_shape_tests
