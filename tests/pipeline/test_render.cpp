// Choosing the frame the demo draws: the belief's spread and the frame where it collapses, on
// beliefs whose answer is known by construction.
#include <fstream>
#include <vector>

#include <gtest/gtest.h>

#include "seqloc/pipeline/npy.hpp"
#include "seqloc/pipeline/render.hpp"
#include "support/test_support.hpp"

namespace seqloc::pipeline {
namespace {

TEST(Render, SpreadCellsCountsTheSmallestSetHoldingTheMass) {
  // 10 equal cells: 9 hold 90 %.
  EXPECT_EQ(spread_cells(std::vector<double>(10, 0.1)), 9u);
  // One cell of 0.95 holds 90 % alone, whatever the scale of the values.
  EXPECT_EQ(spread_cells(std::vector<double>{3.0, 0.05, 0.05, 0.05}), 1u);
  EXPECT_EQ(spread_cells(std::vector<double>{0.0, 0.0, 0.0}), 1u);
  EXPECT_EQ(spread_cells(std::vector<double>{0.4, 0.3, 0.2, 0.1}, 0.5), 2u);
}

// Beliefs of 6 frames on a 20 x 20 window: uniform over 100 cells for frames 0-2, 9 cells on
// frame 3 (the collapse, a ratio of 100/9 = 11), 4 cells on frames 4-5 (ratios 2.25, 1).
TEST(Render, CollapseFrameIsWhereTheKeptBeliefShrinksMost) {
  test::ScratchDir dir;
  constexpr int kFrames = 6, kSide = 20;
  const std::vector<int> spread = {100, 100, 100, 9, 4, 4};
  std::vector<float> beliefs(static_cast<std::size_t>(kFrames * kSide * kSide), 0.0F);
  for (int t = 0; t < kFrames; ++t) {
    for (int c = 0; c < spread[static_cast<std::size_t>(t)]; ++c) {
      beliefs[static_cast<std::size_t>(t * kSide * kSide + 37 + c)] = 1.0F / static_cast<float>(spread[static_cast<std::size_t>(t)]);
    }
  }
  {
    std::ofstream npy(dir / "beliefs.npy", std::ios::binary);
    npy << encode_npy_float32(kFrames, kSide, kSide, beliefs.data());
    std::ofstream csv(dir / "beliefs.csv");
    csv << "frame,origin_u,origin_v\n";
    for (int t = 0; t < kFrames; ++t) csv << t << "," << 10 * t << ",5\n";
  }
  EXPECT_EQ(collapse_frame(dir.path(), kFrames), 3u);
  // Beliefs of another route: the error names the file.
  try {
    (void)collapse_frame(dir.path(), kFrames + 1);
    FAIL() << "beliefs of 6 frames taken for a route of 7";
  } catch (const DataError& e) {
    EXPECT_NE(std::string(e.what()).find("beliefs.npy"), std::string::npos) << e.what();
  }
}

}  // namespace
}  // namespace seqloc::pipeline
