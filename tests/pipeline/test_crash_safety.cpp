// kill -9 in the middle of preprocess, many times: the previous cache stays as it was, nothing
// half-written appears under the final name, and a rerun completes (resuming) to the same cache
// as an uninterrupted build.

#include <signal.h>
#include <sys/wait.h>

#include <chrono>
#include <random>
#include <thread>

#include <gtest/gtest.h>

#include "seqloc/raster/cache.hpp"
#include "support/test_support.hpp"

namespace seqloc::pipeline {
namespace {

const char* kBbox = "11.520,49.995,11.566,50.024";  // ~3.3 x 3.2 km of north-bayreuth: ~1 s of work

TEST(CrashSafety, KillNineNeverDamagesTheCacheAndARerunCompletes) {
  const auto osm = test::shared_osm("north-bayreuth.osm.pbf");
  if (osm.empty()) GTEST_SKIP() << "../shared/data/osm is not available";
  test::ScratchDir dir;
  const auto out = dir / "region.gpkg";
  const std::vector<std::string> base{"preprocess", osm.string(), "-o", out.string(), "--bbox", kBbox, "--no-progress"};

  // The previous good cache, built with another clamp.
  auto previous_args = base;
  previous_args.insert(previous_args.end(), {"--max-distance", "50"});
  ASSERT_EQ(test::run_seqloc(previous_args).exit_code, 0);
  const std::string previous = test::read_file(out);

  auto args = base;
  args.insert(args.end(), {"--overwrite", "--threads", "2"});
  std::mt19937 rng(99);
  std::uniform_int_distribution<int> delay_ms(30, 900);
  int killed_mid_build = 0;
  for (int attempt = 0; attempt < 8; ++attempt) {
    const pid_t pid = test::start_seqloc(args);
    ASSERT_GT(pid, 0);
    std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms(rng)));
    kill(pid, SIGKILL);
    int status = 0;
    waitpid(pid, &status, 0);
    if (WIFSIGNALED(status)) ++killed_mid_build;
    // Either the previous cache, untouched, or (if the build had finished) a complete new one.
    const std::string now = test::read_file(out);
    if (now != previous) {
      raster::CacheReader reader(out);
      EXPECT_EQ(reader.metadata().max_distance_m, 100);
      EXPECT_TRUE(reader.metadata().complete);
      break;
    }
    raster::CacheReader reader(out);
    EXPECT_EQ(reader.metadata().max_distance_m, 50);
  }
  EXPECT_GT(killed_mid_build, 0) << "no run was interrupted: the test proved nothing";

  const auto rerun = test::run_seqloc(args);
  ASSERT_EQ(rerun.exit_code, 0) << rerun.err;
  EXPECT_FALSE(std::filesystem::exists(out.string() + ".partial"));

  // Same tiles as an uninterrupted build.
  const auto clean = dir / "clean.gpkg";
  auto clean_args = base;
  clean_args[3] = clean.string();
  ASSERT_EQ(test::run_seqloc(clean_args).exit_code, 0);
  raster::CacheReader a(out), b(clean);
  ASSERT_EQ(a.grid(), b.grid());
  for (std::int64_t row = 0; row < a.grid().tiles_high(); ++row) {
    for (std::int64_t col = 0; col < a.grid().tiles_wide(); ++col) {
      ASSERT_EQ(a.tile_blob(raster::Layer::classes, col, row), b.tile_blob(raster::Layer::classes, col, row));
      ASSERT_EQ(a.tile_blob(raster::Layer::road_distance, col, row),
                b.tile_blob(raster::Layer::road_distance, col, row));
    }
  }
  EXPECT_EQ(a.roads().size(), b.roads().size());
}

}  // namespace
}  // namespace seqloc::pipeline
