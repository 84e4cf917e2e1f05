// kill -9 in the middle of preprocess and of localize, many times: the previous cache or output
// folder stays as it was, nothing half-written appears under the final name, and a rerun
// completes (preprocess resuming) to the same result as an uninterrupted run.

#include <sys/wait.h>

#include <atomic>
#include <chrono>
#include <csignal>
#include <map>
#include <random>
#include <thread>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "seqloc/ingest/preprocess.hpp"
#include "seqloc/raster/cache.hpp"
#include "support/test_support.hpp"

namespace seqloc {
namespace {

const char* kBbox = "11.520,49.995,11.566,50.024";  // ~3.3 x 3.2 km of north-bayreuth: ~1 s of work

// Starts seqloc with `args`, sends it SIGKILL after `delay_ms`; true when the kill (not the end
// of the run) stopped it.
bool killed_after(const std::vector<std::string>& args, long long delay_ms) {
  const pid_t pid = test::start_seqloc(args);
  if (pid <= 0) {
    ADD_FAILURE() << "cannot start seqloc";
    return false;
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(delay_ms));
  kill(pid, SIGKILL);
  int status = 0;
  waitpid(pid, &status, 0);
  return WIFSIGNALED(status);
}

TEST(CrashSafety, KillNineNeverDamagesTheCacheAndARerunCompletes) {
  const auto osm = test::osm_extract("north-bayreuth.osm.pbf");
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
    if (killed_after(args, delay_ms(rng))) ++killed_mid_build;
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

// Every route folder of a localize output holds the four files of the one mode its summary.json
// names.
bool complete_output(const std::filesystem::path& out, int routes) {
  const auto summary = nlohmann::json::parse(test::read_file(out / "summary.json"));
  if (!summary.contains("modes") || summary["modes"].size() != 1) return false;
  const std::string mode = summary["modes"].begin().key();
  int found = 0;
  for (const auto& entry : std::filesystem::directory_iterator(out)) {
    if (!entry.is_directory()) continue;
    for (const char* file : {"poses.csv", "track.geojson", "trajectory.tum", "metrics.json"}) {
      if (!std::filesystem::is_regular_file(entry.path() / mode / file)) return false;
    }
    ++found;
  }
  return found == routes;
}

TEST(CrashSafety, KillNineDuringLocalizeLeavesThePreviousOutputOrTheNewOne) {
  test::ScratchDir dir;
  const auto sample = std::filesystem::path(SEQLOC_SOURCE_DIR) / "samples" / "rural-valley.osm.pbf";
  const auto cache = dir / "valley.gpkg";
  ASSERT_EQ(test::run_seqloc({"preprocess", sample.string(), "-o", cache.string(), "--no-progress"}).exit_code, 0);
  const int routes = 2;
  ASSERT_EQ(test::run_seqloc({"simulate", cache.string(), "-o", (dir / "routes").string(), "--routes",
                              std::to_string(routes), "--frames", "12", "--no-progress"})
                .exit_code,
            0);
  std::vector<std::string> route_dirs;
  route_dirs.reserve(static_cast<std::size_t>(routes));
  for (int r = 0; r < routes; ++r) route_dirs.push_back((dir / "routes" / ("route_00" + std::to_string(r))).string());
  auto localize = [&](const std::string& mode) {
    std::vector<std::string> args{"localize", cache.string()};
    args.insert(args.end(), route_dirs.begin(), route_dirs.end());
    args.insert(args.end(), {"-o", (dir / "out").string(), "--mode", mode, "--overwrite", "--window", "128",
                             "--headings", "64", "--matcher-size", "64", "--threads", "2", "--no-progress"});
    return args;
  };

  // The previous good output (mode single), timed, so that kills land all over the next run.
  const auto started = std::chrono::steady_clock::now();
  ASSERT_EQ(test::run_seqloc(localize("single")).exit_code, 0);
  const auto took_ms =
      std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::steady_clock::now() - started).count();
  const std::string previous = test::read_file(dir / "out" / "summary.json");

  std::mt19937 rng(7);
  std::uniform_int_distribution<long long> delay_ms(0, std::max<long long>(50, took_ms * 3 / 2));
  int killed = 0, replaced = 0;
  for (int attempt = 0; attempt < 10; ++attempt) {
    if (killed_after(localize(attempt % 2 ? "single" : "seqloc"), delay_ms(rng))) ++killed;
    // Always a complete folder under the final name: the previous one or the new one.
    ASSERT_TRUE(std::filesystem::exists(dir / "out" / "summary.json")) << "attempt " << attempt;
    const bool is_previous = test::read_file(dir / "out" / "summary.json") == previous;
    EXPECT_TRUE(complete_output(dir / "out", routes)) << "attempt " << attempt;
    replaced += is_previous ? 0 : 1;
  }
  EXPECT_GT(killed, 3) << "too few runs were interrupted: the test proved little";

  // A rerun completes and clears what the killed runs left beside the output.
  const auto rerun = test::run_seqloc(localize("seqloc"));
  ASSERT_EQ(rerun.exit_code, 0) << rerun.err;
  EXPECT_TRUE(complete_output(dir / "out", routes));
  EXPECT_TRUE(nlohmann::json::parse(test::read_file(dir / "out" / "summary.json"))["modes"].contains("seqloc"));
  for (const auto& entry : std::filesystem::directory_iterator(dir.path())) {
    EXPECT_EQ(entry.path().filename().string().find("out."), std::string::npos) << "left behind: " << entry.path();
  }
  RecordProperty("killed", killed);
  RecordProperty("completed_between_kills", replaced);
}

TEST(Concurrency, ReadersOfACacheBeingRebuiltSeeOneWholeBuild) {
  // Two builds of the sample region that differ in every road-distance tile; then rebuilds
  // alternate between them onto one path while readers open it and read every tile.
  test::ScratchDir dir;
  const auto sample = std::filesystem::path(SEQLOC_SOURCE_DIR) / "samples" / "rural-valley.osm.pbf";
  auto build = [&](const std::filesystem::path& out, double clamp) {
    ingest::PreprocessOptions options;
    options.input = sample;
    options.output = out;
    options.max_distance_m = clamp;
    options.threads = 1;
    options.overwrite = true;
    (void)ingest::preprocess_region(options);
  };
  using Tiles = std::map<std::pair<std::int64_t, std::int64_t>, std::vector<std::uint8_t>>;
  auto tiles_of = [](raster::CacheReader& reader) {
    Tiles tiles;
    for (std::int64_t row = 0; row < reader.grid().tiles_high(); ++row) {
      for (std::int64_t col = 0; col < reader.grid().tiles_wide(); ++col) {
        tiles[{col, row}] = reader.tile_blob(raster::Layer::road_distance, col, row);
      }
    }
    return tiles;
  };
  build(dir / "a.gpkg", 40);
  build(dir / "b.gpkg", 90);
  raster::CacheReader ra(dir / "a.gpkg"), rb(dir / "b.gpkg");
  const Tiles a = tiles_of(ra), b = tiles_of(rb);
  ASSERT_NE(a, b);
  const auto path = dir / "region.gpkg";
  build(path, 40);

  std::atomic<bool> stop{false};
  std::atomic<int> reads{0}, as_a{0}, as_b{0}, mixed{0}, errors{0};
  std::vector<std::thread> readers;
  readers.reserve(3);
  for (int t = 0; t < 3; ++t) {
    readers.emplace_back([&] {
      while (!stop) {
        try {
          raster::CacheReader reader(path);
          const Tiles seen = tiles_of(reader);
          ++reads;
          if (seen == a) {
            ++as_a;
          } else if (seen == b) {
            ++as_b;
          } else {
            ++mixed;
          }
        } catch (const std::exception& e) {
          ++errors;
          ADD_FAILURE() << "a reader failed while the cache was rebuilt: " << e.what();
        }
      }
    });
  }
  for (int rebuild = 0; rebuild < 6; ++rebuild) build(path, rebuild % 2 ? 40 : 90);
  stop = true;
  for (auto& t : readers) t.join();
  EXPECT_EQ(mixed.load(), 0) << "a reader saw tiles of two builds";
  EXPECT_EQ(errors.load(), 0);
  EXPECT_GT(as_a.load(), 0) << "reads: " << reads;
  EXPECT_GT(as_b.load(), 0) << "reads: " << reads;
}

}  // namespace
}  // namespace seqloc
