// The sample region in samples/ is what our generator writes: regenerating it gives the same
// features, and it holds what the demo needs (a road network with an intersection, forest,
// meadows, buildings). The generator's mountain pass (development draws) is the same file on
// every run and holds few features for its length of road.

#include <algorithm>
#include <map>

#include <gtest/gtest.h>

#include "seqloc/osm/reader.hpp"
#include "support/test_support.hpp"

namespace seqloc::osm {
namespace {

const std::filesystem::path kSample = std::filesystem::path(SEQLOC_SOURCE_DIR) / "samples" / "rural-valley.osm.pbf";

std::map<std::string, int> census(const FeatureSet& f) {
  std::map<std::string, int> count;
  for (const auto& p : f.points) ++count[std::string(group_name(p.group))];
  for (const auto& l : f.lines) ++count[std::string(group_name(l.group))];
  for (const auto& a : f.areas) ++count["area:" + std::string(group_name(a.group))];
  return count;
}

TEST(Sample, RegeneratesToTheCommittedFeatures) {
  test::ScratchDir dir;
  const auto fresh = dir / "sample.osm.pbf";
  const auto made = test::run_program(SEQLOC_MAKE_SAMPLE, {fresh.string()});
  ASSERT_EQ(made.exit_code, 0) << made.err;

  const auto committed = read_osm(kSample);
  const auto regenerated = read_osm(fresh);
  EXPECT_EQ(census(committed), census(regenerated));
  ASSERT_EQ(committed.lines.size(), regenerated.lines.size());
  for (std::size_t i = 0; i < committed.lines.size(); ++i) {
    ASSERT_EQ(committed.lines[i].points.size(), regenerated.lines[i].points.size());
    for (std::size_t k = 0; k < committed.lines[i].points.size(); ++k) {
      EXPECT_EQ(committed.lines[i].points[k].lat_deg, regenerated.lines[i].points[k].lat_deg);
      EXPECT_EQ(committed.lines[i].points[k].lon_deg, regenerated.lines[i].points[k].lon_deg);
    }
  }
}

TEST(Sample, IsARuralRegionWithWhatTheDemoNeeds) {
  const auto count = census(read_osm(kSample));
  EXPECT_GE(count.at("road"), 5);
  EXPECT_GE(count.at("path"), 1);
  EXPECT_GE(count.at("area:forest"), 2);
  EXPECT_GE(count.at("area:grass"), 2);
  EXPECT_GE(count.at("area:building"), 10);
  EXPECT_GE(count.at("tree"), 50);
  EXPECT_GE(count.at("hedge"), 1);
  EXPECT_GE(count.at("fence"), 1);
}

TEST(Sample, TheMountainPassIsTheSameOnEveryRunAndSeesFewFeatures) {
  test::ScratchDir dir;
  const auto first = dir / "first.osm.pbf", second = dir / "second.osm.pbf";
  for (const auto& path : {first, second}) {
    const auto made = test::run_program(SEQLOC_MAKE_SAMPLE, {"--region", "mountain-pass", path.string()});
    ASSERT_EQ(made.exit_code, 0) << made.err;
  }
  EXPECT_EQ(test::read_file(first), test::read_file(second));

  const auto pass = census(read_osm(first));
  const auto valley = census(read_osm(kSample));
  EXPECT_EQ(pass.at("road"), 7);  // the serpentine, the valley road, its link, the top road, three tracks
  EXPECT_EQ(pass.at("area:forest"), 12);
  EXPECT_EQ(pass.at("area:building"), 5);
  EXPECT_EQ(pass.at("tree"), 16);
  EXPECT_LT(pass.at("tree") + pass.at("area:building"), (valley.at("tree") + valley.at("area:building")) / 3);
}

TEST(Sample, TheGeneratorRefusesAnUnknownRegion) {
  test::ScratchDir dir;
  const auto made = test::run_program(SEQLOC_MAKE_SAMPLE, {"--region", "atlantis", (dir / "x.osm.pbf").string()});
  EXPECT_EQ(made.exit_code, 2);
  EXPECT_NE(made.err.find("usage"), std::string::npos);
  EXPECT_FALSE(std::filesystem::exists(dir / "x.osm.pbf"));
}

}  // namespace
}  // namespace seqloc::osm
