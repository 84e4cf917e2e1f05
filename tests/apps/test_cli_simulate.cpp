// seqloc simulate, localize on observation routes, and render, from the command line on the
// sample region (the demo's path); and the errors a user can make on the way.

#include <algorithm>
#include <fstream>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "seqloc/render/render.hpp"

#include "support/test_support.hpp"

namespace seqloc {
namespace {

using test::run_seqloc;

std::vector<std::string> split(const std::string& text, char separator) {
  std::vector<std::string> parts;
  std::stringstream in(text);
  for (std::string part; std::getline(in, part, separator);) parts.push_back(part);
  return parts;
}

TEST(CliSimulate, SampleRegionToTableAndPictures) {
  test::ScratchDir dir;
  const auto cache = (dir / "sample.gpkg").string();
  auto r = run_seqloc({"preprocess", std::string(SEQLOC_SOURCE_DIR) + "/samples/rural-valley.osm.pbf", "-o", cache});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const auto routes = (dir / "routes").string();
  r = run_seqloc({"simulate", cache, "-o", routes, "--routes", "2", "--frames", "10", "--seed", "3"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.out.find("2 routes of 10 frames"), std::string::npos) << r.out;
  // Again without --overwrite: a usage error, the routes untouched.
  const std::string before = test::read_file(dir / "routes/route_001/frames.csv");
  r = run_seqloc({"simulate", cache, "-o", routes, "--routes", "1", "--frames", "5"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("--overwrite"), std::string::npos) << r.err;
  EXPECT_EQ(test::read_file(dir / "routes/route_001/frames.csv"), before);

  const auto out = (dir / "localized").string();
  r = run_seqloc({"localize", cache, routes + "/route_000", routes + "/route_001", "-o", out, "--mode", "all",
                  "--window", "192", "--threads", "2"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* mode : {"single", "offline", "online", "seqloc", "smooth"}) {
    EXPECT_NE(r.out.find(std::string("\n") + mode), std::string::npos) << r.out;
    EXPECT_TRUE(std::filesystem::exists(dir / "localized/route_000" / mode / "poses.csv")) << mode;
  }
  // The modes share each route's volumes, scored once: a mode alone gives the same poses, and so
  // do frames spilled to the temporary file (--frame-memory 0) instead of kept in memory.
  const auto alone = (dir / "alone").string(), spilled = (dir / "spilled").string();
  r = run_seqloc({"localize", cache, routes + "/route_001", "-o", alone, "--mode", "seqloc", "--window", "192", "--beliefs"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(test::read_file(dir / "alone/route_001/seqloc/poses.csv"),
            test::read_file(dir / "localized/route_001/seqloc/poses.csv"));
  r = run_seqloc({"-v", "localize", cache, routes + "/route_000", routes + "/route_001", "-o", spilled, "--mode", "all",
                  "--window", "192", "--threads", "2", "--frame-memory", "0", "--beliefs"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("20 volumes scored or read for 20 frames and 5 modes; 20 spilled"), std::string::npos) << r.err;
  for (const char* route : {"route_000", "route_001"}) {
    for (const char* mode : {"single", "offline", "online", "seqloc", "smooth"}) {
      EXPECT_EQ(test::read_file(dir / "spilled" / route / mode / "poses.csv"),
                test::read_file(dir / "localized" / route / mode / "poses.csv"))
          << route << "/" << mode;
    }
  }
  // To the last bit: a mode run beside others on other threads (and other heap addresses) keeps
  // the beliefs and the full-precision metrics of the same mode alone.
  for (const char* file : {"beliefs.npy", "metrics.json"}) {
    EXPECT_EQ(test::read_file(dir / "alone/route_001/seqloc" / file), test::read_file(dir / "spilled/route_001/seqloc" / file))
        << file;
  }
  r = run_seqloc({"render", cache, routes + "/route_001", "--localized", out, "-o", (dir / "figures").string(), "--frame",
                  "4", "--window", "192"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* file : {"likelihood_4.png", "entropy_route.png", "error_over_time.png"}) {
    EXPECT_TRUE(std::filesystem::exists(dir / "figures" / file)) << file;
  }
  // With the beliefs localize kept (--beliefs), render draws them; without them (above) it runs
  // seqloc with --beliefs itself first: the same picture, byte for byte.
  EXPECT_TRUE(std::filesystem::exists(dir / "spilled/route_001/seqloc/beliefs.npy"));
  EXPECT_FALSE(std::filesystem::exists(dir / "spilled/route_001/single/beliefs.npy"));
  r = run_seqloc({"render", cache, routes + "/route_001", "--localized", spilled, "-o", (dir / "kept").string(),
                  "--frame", "4", "--window", "192"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(test::read_file(dir / "kept/likelihood_4.png"), test::read_file(dir / "figures/likelihood_4.png"));
  // Beliefs that do not belong to the route: one clear error naming the file.
  std::ofstream(dir / "spilled/route_001/seqloc/beliefs.csv") << "frame,origin_u,origin_v\n0,1,2\n";
  r = run_seqloc({"render", cache, routes + "/route_001", "--localized", spilled, "-o", (dir / "kept").string(),
                  "--frame", "4", "--window", "192"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("beliefs.csv: 1 rows for a route of 10 frames"), std::string::npos) << r.err;
  r = run_seqloc({"render", cache, routes + "/route_001", "-o", (dir / "figures").string(), "--frame", "10"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("frame 10"), std::string::npos) << r.err;
  r = run_seqloc({"render", cache, routes + "/route_001", "-o", (dir / "figures").string(), "--frame", "ten"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("sharpest"), std::string::npos) << r.err;
  // 'sharpest': the frame after the first with the lowest entropy, read here from poses.csv.
  std::ifstream poses(dir / "localized/route_001/seqloc/poses.csv");
  std::string line;
  std::getline(poses, line);
  const auto header = split(line, ',');
  const auto column = static_cast<std::size_t>(std::find(header.begin(), header.end(), "entropy") - header.begin());
  ASSERT_LT(column, header.size());
  std::size_t sharpest = 0, index = 0;
  double lowest = 2;
  while (std::getline(poses, line)) {
    const double entropy = std::stod(split(line, ',').at(column));
    if (index > 0 && entropy < lowest) lowest = entropy, sharpest = index;
    ++index;
  }
  ASSERT_GT(sharpest, 0u);
  const auto sharp_dir = dir / "sharpest";
  r = run_seqloc({"render", cache, routes + "/route_001", "--localized", out, "-o", sharp_dir.string(), "--frame",
                  "sharpest", "--window", "192"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(std::filesystem::exists(sharp_dir / ("likelihood_" + std::to_string(sharpest) + ".png"))) << r.out;
  // 'collapse': where the kept SeqLoc belief shrinks most; from a run without kept beliefs, render
  // runs seqloc itself and finds the same frame.
  const auto collapse = render::collapse_frame(dir / "spilled/route_000/seqloc", 10);
  r = run_seqloc({"render", cache, routes + "/route_000", "--localized", spilled, "-o", (dir / "collapse").string(),
                  "--frame", "collapse", "--window", "192"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_TRUE(std::filesystem::exists(dir / "collapse" / ("likelihood_" + std::to_string(collapse) + ".png"))) << r.out;
  r = run_seqloc({"render", cache, routes + "/route_000", "--localized", out, "-o", (dir / "collapse_here").string(),
                  "--frame", "collapse", "--window", "192"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(test::read_file(dir / "collapse_here" / ("likelihood_" + std::to_string(collapse) + ".png")),
            test::read_file(dir / "collapse" / ("likelihood_" + std::to_string(collapse) + ".png")));
}

TEST(CliSimulate, ABadObservationStopsLocalizeWithNothingWritten) {
  test::ScratchDir dir;
  const auto cache = (dir / "sample.gpkg").string();
  auto r = run_seqloc({"preprocess", std::string(SEQLOC_SOURCE_DIR) + "/samples/rural-valley.osm.pbf", "-o", cache});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  r = run_seqloc({"simulate", cache, "-o", (dir / "routes").string(), "--routes", "1", "--frames", "6"});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  std::ofstream(dir / "routes/route_000/observations/000003.png", std::ios::trunc) << "not a png";
  r = run_seqloc({"localize", cache, (dir / "routes/route_000").string(), "-o", (dir / "out").string()});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("000003.png"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(dir / "out"));
  // Options out of range are usage errors.
  r = run_seqloc({"simulate", cache, "-o", (dir / "r2").string(), "--class-miss", "2"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("class_miss"), std::string::npos) << r.err;
  r = run_seqloc({"localize", cache, (dir / "routes/route_000").string(), "-o", (dir / "out").string(),
                  "--matcher-temperature", "0"});
  EXPECT_EQ(r.exit_code, 2);
  EXPECT_NE(r.err.find("temperature"), std::string::npos) << r.err;
}

}  // namespace
}  // namespace seqloc
