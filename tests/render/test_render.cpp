// Choosing the frame the demo draws: the belief's spread and the frame where it collapses, on
// beliefs whose answer is known by construction; and the route overview, on a synthetic map whose
// every feature is known, with estimates placed at known errors.
#include <algorithm>
#include <fstream>
#include <vector>

#include <gtest/gtest.h>

#include "seqloc/ingest/preprocess.hpp"
#include "seqloc/io/npy.hpp"
#include "seqloc/osm/classes.hpp"
#include "seqloc/osm/synthetic.hpp"
#include "seqloc/raster/palette.hpp"
#include "seqloc/render/render.hpp"
#include "support/test_support.hpp"

namespace seqloc::render {
namespace {

TEST(Render, SpreadCellsCountsTheSmallestSetHoldingTheMass) {
  // 10 equal cells: 9 hold 90 %.
  EXPECT_EQ(render::spread_cells(std::vector<double>(10, 0.1)), 9u);
  // One cell of 0.95 holds 90 % alone, whatever the scale of the values.
  EXPECT_EQ(render::spread_cells(std::vector<double>{3.0, 0.05, 0.05, 0.05}), 1u);
  EXPECT_EQ(render::spread_cells(std::vector<double>{0.0, 0.0, 0.0}), 1u);
  EXPECT_EQ(render::spread_cells(std::vector<double>{0.4, 0.3, 0.2, 0.1}, 0.5), 2u);
}

// Beliefs of 6 frames on a 20 x 20 window: uniform over 100 cells for frames 0-2, 9 cells on
// frame 3 (the collapse, a ratio of 100/9 = 11), 4 cells on frames 4-5 (ratios 2.25, 1).
TEST(Render, CollapseFrameIsWhereTheKeptBeliefShrinksMostOntoTheTruth) {
  test::ScratchDir dir;
  constexpr int kFrames = 6, kSide = 20;
  const std::vector<int> spread = {100, 100, 100, 9, 4, 4};
  std::vector<float> beliefs(static_cast<std::size_t>(kFrames * kSide * kSide), 0.0F);
  for (int t = 0; t < kFrames; ++t) {
    for (int c = 0; c < spread[static_cast<std::size_t>(t)]; ++c) {
      beliefs[static_cast<std::size_t>(t * kSide * kSide + 37 + c)] =
          1.0F / static_cast<float>(spread[static_cast<std::size_t>(t)]);
    }
  }
  {
    std::ofstream npy(dir / "beliefs.npy", std::ios::binary);
    npy << io::encode_npy_float32(kFrames, kSide, kSide, beliefs.data());
    std::ofstream csv(dir / "beliefs.csv");
    csv << "frame,origin_u,origin_v\n";
    for (int t = 0; t < kFrames; ++t) csv << t << "," << 10 * t << ",5\n";
  }
  EXPECT_EQ(render::collapse_frame(dir.path(), kFrames), 3u);
  // SeqLoc's errors: on frame 3 the belief shrinks onto the wrong place (20 -> 30 m); on frame 4
  // it shrinks onto the truth (30 -> 2 m), the figure that shows the method.
  std::vector<io::FramePose> poses(kFrames);
  const double errors[kFrames] = {20, 20, 20, 30, 2, 1};
  for (int t = 0; t < kFrames; ++t) poses[static_cast<std::size_t>(t)].position_error_m = errors[t];
  EXPECT_EQ(render::collapse_frame(dir.path(), kFrames, poses), 4u);
  EXPECT_EQ(render::collapse_frame(dir.path(), kFrames, poses, 1.5), 5u) << "only frame 5 falls to 1.5 m or less";
  EXPECT_EQ(render::collapse_frame(dir.path(), kFrames, poses, 0.5), 3u)
      << "no frame falls that far: the largest shrink";
  // No frame brings the error from beyond 5 m to within it: the largest shrink among those where
  // it falls (frames 4 and 5), not frame 3, where it rises.
  const double small[kFrames] = {4, 4, 4, 4.5, 2, 1};
  for (int t = 0; t < kFrames; ++t) poses[static_cast<std::size_t>(t)].position_error_m = small[t];
  EXPECT_EQ(render::collapse_frame(dir.path(), kFrames, poses), 4u);
  // Beliefs of another route: the error names the file.
  try {
    (void)render::collapse_frame(dir.path(), kFrames + 1);
    FAIL() << "beliefs of 6 frames taken for a route of 7";
  } catch (const DataError& e) {
    EXPECT_NE(std::string(e.what()).find("beliefs.npy"), std::string::npos) << e.what();
  }
}

TEST(Render, ScaleBarIsARoundLengthNearAFifthOfTheWidth) {
  // 1400 px at 0.25 m: a fifth is 70 m; 50 m and 100 m are the round lengths around it, and 50 m
  // is nearer (a ratio of 1.4 against 1.43).
  EXPECT_EQ(render::scale_bar_for(1400, 0.25).metres, 50.0);
  EXPECT_EQ(render::scale_bar_for(1400, 0.25).pixels, 200);
  EXPECT_EQ(render::scale_bar_for(1000, 1.0).metres, 200.0);
  EXPECT_EQ(render::scale_bar_for(500, 10.0).metres, 1000.0);
  EXPECT_EQ(render::scale_bar_for(500, 10.0).pixels, 100);
  for (const double mpp : {0.1, 0.27, 0.5, 3.3, 17.0}) {
    const render::ScaleBar bar = render::scale_bar_for(900, mpp);
    EXPECT_LE(bar.pixels, 300) << mpp;
    EXPECT_GE(bar.pixels, 900 / 5 / 3) << mpp;
    EXPECT_NEAR(bar.pixels * mpp, bar.metres, mpp) << mpp;
  }
  EXPECT_EQ(render::scale_bar_for(0, 1.0).pixels, 0);
}

std::array<std::uint8_t, 3> pixel(const render::Picture& p, double x, double y) {
  const auto i = (static_cast<std::size_t>(y) * static_cast<std::size_t>(p.width) + static_cast<std::size_t>(x)) * 3;
  return {p.rgb[i], p.rgb[i + 1], p.rgb[i + 2]};
}

std::array<std::uint8_t, 3> class_colour(std::uint8_t area, std::uint8_t way) {
  const std::array<std::uint8_t, 3> codes{area, way, 0};
  const auto c = raster::class_colours(codes);
  return {c[0], c[1], c[2]};
}

// A road east-west through the map's centre, a forest north-west of it and a building south-east;
// the route's truth every 30 m along the road, each estimate north of it by a known error.
TEST(Render, OverviewDrawsTheMapAndEachEstimateInItsErrorsColourWhereTheyAre) {
  test::ScratchDir dir;
  constexpr double kLat0 = 47.5, kLon0 = 10.5;
  osm::SyntheticMap map(kLat0, kLon0);
  map.way({{-300, 0.25}, {300, 0.25}}, {{"highway", "track"}});  // along a row of cell centres
  map.way({{-120, 15}, {-40, 15}, {-40, 40}, {-120, 40}}, {{"landuse", "forest"}}, /*closed=*/true);
  map.way({{60, -35}, {100, -35}, {100, -15}, {60, -15}}, {{"building", "yes"}}, /*closed=*/true);
  map.write(dir / "map.osm.pbf");
  ingest::PreprocessOptions options;
  options.input = dir / "map.osm.pbf";
  options.output = dir / "map.gpkg";
  options.bbox = osm::GeoBox{kLon0 - 0.005, kLat0 - 0.003, kLon0 + 0.005, kLat0 + 0.003};
  (void)ingest::preprocess_region(options);
  raster::CacheReader cache(options.output);

  io::Route route;
  route.name = "known";
  std::vector<io::FramePose> poses;
  const double errors[] = {0.5, 2.0, 4.0, 8.0};
  for (int i = 0; i < 11; ++i) {
    const double x = -150 + 30.0 * i, error = errors[i % 4];
    io::RouteFrame f;
    f.truth = io::GroundTruth{map.to_geo({x, 0.25}), 90.0};
    route.frames.push_back(f);
    io::FramePose p;
    const auto at = map.to_geo({x, 0.25 + error});
    p.lat_deg = at.lat_deg;
    p.lon_deg = at.lon_deg;
    p.position_error_m = error;
    poses.push_back(p);
  }
  const render::MapFigure figure = render::route_overview(cache, route, "seqloc", poses);
  const render::Picture& picture = figure.picture;
  const render::MapView& view = figure.view;
  const auto& grid = cache.grid();
  auto at = [&](double x, double y) { return view.at(grid.region_u(x), grid.region_v(y)); };

  for (std::size_t i = 0; i < poses.size(); ++i) {
    const auto p = at(-150 + 30.0 * static_cast<double>(i), 0.25 + errors[i % 4]);
    EXPECT_EQ(pixel(picture, p[0], p[1]), render::error_colour(errors[i % 4])) << "frame " << i;
  }
  EXPECT_NE(render::error_colour(0.5), render::error_colour(2.0));
  EXPECT_NE(render::error_colour(4.0), render::error_colour(8.0));
  // Classes as recall counts them (error < t): an error of exactly 1 or 5 m is in the class above.
  EXPECT_EQ(render::error_colour(1.0), render::error_colour(2.0));
  EXPECT_EQ(render::error_colour(5.0), render::error_colour(8.0));
  const auto forest = osm::find_group("forest"), building = osm::find_group("building");
  ASSERT_TRUE(forest && building);
  const auto f = at(-80, 28), b = at(80, -25);
  EXPECT_EQ(pixel(picture, f[0], f[1]), class_colour(forest->code(), 0)) << "forest at " << f[0] << ", " << f[1];
  EXPECT_EQ(pixel(picture, b[0], b[1]), class_colour(building->code(), 0)) << "building at " << b[0] << ", " << b[1];
  const auto road = at(175, 0.25);  // beyond the route's last estimate, within the map
  EXPECT_EQ(pixel(picture, road[0], road[1]), class_colour(0, osm::kRoad.code()));
  const auto empty = at(0, -30);
  EXPECT_EQ(pixel(picture, empty[0], empty[1]), class_colour(0, 0)) << "background";

  // The scale bar: a run of black exactly as long as scale_bar_for says, in the map's lower left
  // (the map spans the picture's width; its lowest 10 m lie below the route's black line).
  const render::ScaleBar bar = render::scale_bar_for(picture.width, view.metres_per_px());
  int longest = 0;
  for (auto y = static_cast<int>(at(0, -30)[1]); y < static_cast<int>(at(0, -40)[1]); ++y) {
    int run = 0;
    for (int x = 0; x < picture.width / 2; ++x) {
      run = pixel(picture, x, y) == std::array<std::uint8_t, 3>{0, 0, 0} ? run + 1 : 0;
      longest = std::max(longest, run);
    }
  }
  EXPECT_EQ(longest, bar.pixels) << bar.metres << " m at " << view.metres_per_px() << " m per pixel";
}

}  // namespace
}  // namespace seqloc::render
