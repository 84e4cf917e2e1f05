// The exact distance transform against brute force on random masks.

#include <random>

#include <gtest/gtest.h>

#include "seqloc/raster/distance_transform.hpp"

namespace seqloc::raster {
namespace {

std::vector<std::uint8_t> random_mask(std::mt19937& rng, int w, int h, double density) {
  std::bernoulli_distribution mark(density);
  std::vector<std::uint8_t> mask(static_cast<std::size_t>(w * h));
  for (auto& m : mask) m = mark(rng) ? 1 : 0;
  return mask;
}

TEST(DistanceTransform, ExactAgainstBruteForceOnRandomMasks) {
  std::mt19937 rng(2024);
  DistanceScratch scratch;
  std::vector<std::uint32_t> squared;
  for (int trial = 0; trial < 40; ++trial) {
    const int w = 20 + trial * 3, h = 15 + trial * 2;
    const double density = trial % 4 == 0 ? 0.001 : (trial % 4 == 1 ? 0.01 : 0.1);
    auto mask = random_mask(rng, w, h, density);
    if (trial == 5) std::fill(mask.begin(), mask.end(), 0);  // no mark at all
    const auto reference = brute_force_distance_m(mask, w, h, 0.5);
    squared_distance(mask, w, h, 0, 0, w, h, scratch, squared);
    for (std::size_t i = 0; i < squared.size(); ++i) {
      if (reference[i] > 1e100) {
        EXPECT_EQ(squared[i], kNoMark);
      } else {
        ASSERT_NE(squared[i], kNoMark);
        // Exact to 1 cm before quantization (in fact to rounding of a square root).
        EXPECT_NEAR(std::sqrt(static_cast<double>(squared[i])) * 0.5, reference[i], 1e-9) << "trial " << trial;
      }
    }
  }
}

TEST(DistanceTransform, SubRectangleSeesMarksOutsideIt) {
  std::mt19937 rng(5);
  DistanceScratch scratch;
  const int w = 90, h = 70;
  const auto mask = random_mask(rng, w, h, 0.003);
  const auto reference = brute_force_distance_m(mask, w, h, 0.5);
  std::vector<std::uint32_t> squared;
  squared_distance(mask, w, h, 20, 15, 40, 30, scratch, squared);
  for (int v = 0; v < 30; ++v) {
    for (int u = 0; u < 40; ++u) {
      const double expected = reference[static_cast<std::size_t>((v + 15) * w + u + 20)];
      const auto got = squared[static_cast<std::size_t>(v * 40 + u)];
      if (expected > 1e100) {
        EXPECT_EQ(got, kNoMark);
      } else {
        EXPECT_NEAR(std::sqrt(static_cast<double>(got)) * 0.5, expected, 1e-9);
      }
    }
  }
}

TEST(DistanceTransform, QuantizesToCentimetresWithClamp) {
  EXPECT_EQ(quantize_distance_cm(0, 0.5, 10000), 0);
  EXPECT_EQ(quantize_distance_cm(1, 0.5, 10000), 50);
  EXPECT_EQ(quantize_distance_cm(2, 0.5, 10000), 71);  // 0.7071 m
  EXPECT_EQ(quantize_distance_cm(5, 0.5, 10000), 112);  // 1.1180 m
  EXPECT_EQ(quantize_distance_cm(200 * 200, 0.5, 10000), 10000);
  EXPECT_EQ(quantize_distance_cm(201 * 201, 0.5, 10000), 10000);
  EXPECT_EQ(quantize_distance_cm(kNoMark, 0.5, 10000), 10000);
}

}  // namespace
}  // namespace seqloc::raster

namespace seqloc::raster {
namespace {

TEST(DistanceTransform, ReachLimitedTransformIsExactAfterClamping) {
  std::mt19937 rng(77);
  DistanceScratch scratch;
  std::vector<std::uint32_t> full, limited;
  const DistanceQuantizer quantize(0.5, 1000);  // clamp 10 m = 20 cells
  ASSERT_EQ(quantize.reach_cells(), 20);
  for (int trial = 0; trial < 30; ++trial) {
    const int w = 60 + trial, h = 50 + 2 * trial;
    const auto mask = random_mask(rng, w, h, trial % 2 ? 0.002 : 0.02);
    const auto reference = brute_force_distance_m(mask, w, h, 0.5);
    squared_distance(mask, w, h, 10, 12, w - 25, h - 20, scratch, limited, quantize.reach_cells());
    for (int v = 0; v < h - 20; ++v) {
      for (int u = 0; u < w - 25; ++u) {
        const double metres = reference[static_cast<std::size_t>((v + 12) * w + u + 10)];
        const std::uint16_t expected =
            metres > 1e100 ? 1000 : static_cast<std::uint16_t>(std::min(1000.0, std::floor(metres * 100 + 0.5)));
        ASSERT_EQ(quantize(limited[static_cast<std::size_t>(v * (w - 25) + u)]), expected) << trial;
      }
    }
  }
}

TEST(DistanceTransform, QuantizerTableEqualsTheFormula) {
  const DistanceQuantizer quantize(0.5, 10000);
  for (std::uint32_t d2 = 0; d2 < 50000; ++d2) ASSERT_EQ(quantize(d2), quantize_distance_cm(d2, 0.5, 10000)) << d2;
  EXPECT_EQ(quantize(kNoMark), 10000);
}

}  // namespace
}  // namespace seqloc::raster
