// The seqloc command line: --help everywhere, exit codes (0 ok, 1 failure, 2 usage), one-line
// errors on stderr, and the files each command writes.

#include <gtest/gtest.h>

#include <fstream>
#include <nlohmann/json.hpp>

#include "seqloc/filter/config.hpp"
#include "seqloc/osm/reader.hpp"
#include "seqloc/osm/synthetic.hpp"
#include "seqloc/raster/cache.hpp"
#include "support/test_support.hpp"

namespace seqloc {
namespace {

using test::run_seqloc;

std::filesystem::path small_map(const test::ScratchDir& dir) {
  osm::SyntheticMap map(47.5, 10.5);
  map.way({{-200, 0}, {0, 30}, {200, 0}}, {{"highway", "track"}});
  map.way({{10, 10}, {20, 10}, {20, 20}, {10, 20}}, {{"building", "yes"}}, true);
  auto path = dir / "map.osm.pbf";
  map.write(path, 100);
  return path;
}

int count_lines(const std::string& s) { return static_cast<int>(std::count(s.begin(), s.end(), '\n')); }

TEST(Cli, HelpOnEverySubcommand) {
  for (const std::vector<std::string>& args : {std::vector<std::string>{"--help"},
                                               {"preprocess", "--help"},
                                               {"cache", "--help"},
                                               {"cache", "info", "--help"},
                                               {"cache", "merge", "--help"},
                                               {"localize", "--help"},
                                               {"evaluate", "--help"},
                                               {"simulate", "--help"},
                                               {"render", "--help"},
                                               {"serve", "--help"},
                                               {"export", "--help"},
                                               {"match", "--help"},
                                               {"update", "--help"}}) {
    const auto r = run_seqloc(args);
    EXPECT_EQ(r.exit_code, 0) << args[0];
    EXPECT_NE(r.out.find("Usage"), std::string::npos) << r.out;
  }
  const auto help = run_seqloc({"preprocess", "--help"}).out;
  for (const char* option : {"--bbox", "--max-distance", "--corridor", "--threads", "--shard", "--progress",
                             "--overwrite", "--report", "-o"}) {
    EXPECT_NE(help.find(option), std::string::npos) << option;
  }
  const auto simulate = run_seqloc({"simulate", "--help"}).out;
  for (const char* option :
       {"--routes", "--frames", "--seed", "--range", "--fov", "--class-miss", "--wrong-frames", "--clean"}) {
    EXPECT_NE(simulate.find(option), std::string::npos) << option;
  }
  const auto render = run_seqloc({"render", "--help"}).out;
  for (const char* option : {"--localized", "--frame", "collapse", "sharpest", "-o"}) {
    EXPECT_NE(render.find(option), std::string::npos) << option;
  }
  const auto localize = run_seqloc({"localize", "--help"}).out;
  for (const char* option :
       {"--matcher-temperature", "--volume-temperature", "--etu-reference", "--outside-crop-nats", "--matcher-floor",
        "--shard", "--frame-memory", "--beliefs", "--no-self-calibrate", "--paper", "--region",
        "folder of region caches", "--mcap", "--mcap-frame-id", "--mcap-base-frame", "--mcap-origin"}) {
    EXPECT_NE(localize.find(option), std::string::npos) << option;
  }
  const auto update = run_seqloc({"update", "--help"}).out;
  for (const char* option : {"--base", "--changes", "--state", "-o", "--new-base", "--threads", "--progress"}) {
    EXPECT_NE(update.find(option), std::string::npos) << option;
  }
  const auto match = run_seqloc({"match", "--help"}).out;
  for (const char* option :
       {"-o", "--matcher-temperature", "--matcher-floor", "--threads", "--overwrite", "--progress"}) {
    EXPECT_NE(match.find(option), std::string::npos) << option;
  }
  const auto serve = run_seqloc({"serve", "--help"}).out;
  for (const char* option : {"--bind", "--port", "--threads", "--header-timeout", "--keep-alive", "--max-connections",
                             "--max-per-client", "--timeout", "--max-crop-m", "--web"}) {
    EXPECT_NE(serve.find(option), std::string::npos) << option;
  }
  const auto exporter = run_seqloc({"export", "--help"}).out;
  for (const char* option : {"--layer", "--bbox", "--float", "-o", "--overwrite"}) {
    EXPECT_NE(exporter.find(option), std::string::npos) << option;
  }
  EXPECT_NE(run_seqloc({"--version"}).out.find("seqloc "), std::string::npos);
}

// localize's filter options come from the filter's field table: each setting has its option, and
// each option sets its own field (-1 breaks every numeric field's rule, and the usage error names
// the field that validate() found, before the cache or routes are read).
TEST(Cli, LocalizeHasAnOptionForEachFilterSetting) {
  const auto help = run_seqloc({"localize", "--help"}).out;
  const filter::FilterConfig defaults;
  int numeric = 0;
  for (const auto& field : filter::filter_config_fields()) {
    const std::string name = field.name;
    if (name == "width" || name == "height" || name == "threads") continue;  // --window, --threads
    std::string flag = name;
    std::replace(flag.begin(), flag.end(), '_', '-');
    const bool* on = std::holds_alternative<bool filter::FilterConfig::*>(field.member)
                         ? &(defaults.*std::get<bool filter::FilterConfig::*>(field.member))
                         : nullptr;
    const std::string option = on != nullptr && *on ? "--no-" + flag : "--" + flag;
    EXPECT_NE(help.find(option), std::string::npos) << option;
    if (on != nullptr) continue;
    ++numeric;
    const auto bad =
        run_seqloc({"localize", "/nonexistent.gpkg", "/nonexistent-route", "-o", "/tmp/never", option + "=-1"});
    EXPECT_EQ(bad.exit_code, 2) << option;
    EXPECT_NE(bad.err.find(name + " = -1"), std::string::npos) << option << ": " << bad.err;
  }
  EXPECT_GE(numeric, 9);
  // The names of earlier releases still work.
  EXPECT_NE(run_seqloc({"localize", "/nonexistent.gpkg", "/r", "-o", "/tmp/never", "--epsilon", "2"})
                .err.find("mgr_epsilon = 2"),
            std::string::npos);
  EXPECT_NE(run_seqloc({"localize", "/nonexistent.gpkg", "/r", "-o", "/tmp/never", "--sigma=-1"})
                .err.find("mgr_sigma_m = -1"),
            std::string::npos);
  // --paper sets the paper's values whatever the options say: an ETU reference of 2 is refused
  // alone, and overridden (so the run goes on to fail on the missing cache) with --paper.
  const auto alone = run_seqloc({"localize", "/nonexistent.gpkg", "/r", "-o", "/tmp/never", "--etu-reference", "2"});
  EXPECT_EQ(alone.exit_code, 2);
  EXPECT_NE(alone.err.find("etu_reference_entropy = 2"), std::string::npos) << alone.err;
  const auto paper =
      run_seqloc({"localize", "/nonexistent.gpkg", "/r", "-o", "/tmp/never", "--etu-reference", "2", "--paper"});
  EXPECT_EQ(paper.err.find("etu_reference_entropy"), std::string::npos) << paper.err;
  EXPECT_NE(paper.err.find("nonexistent"), std::string::npos) << paper.err;
}

TEST(Cli, ServeRefusesWhatItCannotServe) {
  const auto missing = run_seqloc({"serve", "/nonexistent/region.gpkg"});
  EXPECT_EQ(missing.exit_code, 2);  // CLI11 checks that the file exists
  test::ScratchDir dir;
  { std::ofstream(dir / "junk.gpkg") << "not a GeoPackage"; }
  const auto junk = run_seqloc({"serve", (dir / "junk.gpkg").string(), "--port", "0"});
  EXPECT_EQ(junk.exit_code, 1);
  EXPECT_NE(junk.err.find("junk.gpkg"), std::string::npos) << junk.err;
  EXPECT_EQ(count_lines(junk.err), 1) << junk.err;
  const auto bad_threads = run_seqloc({"serve", (dir / "junk.gpkg").string(), "--threads", "0"});
  EXPECT_EQ(bad_threads.exit_code, 2);
  EXPECT_NE(bad_threads.err.find("--threads"), std::string::npos) << bad_threads.err;
}

TEST(Cli, UsageErrorsExitTwo) {
  EXPECT_EQ(run_seqloc({}).exit_code, 2);
  EXPECT_EQ(run_seqloc({"preprocess"}).exit_code, 2);
  EXPECT_EQ(run_seqloc({"frobnicate"}).exit_code, 2);
  test::ScratchDir dir;
  const auto map = small_map(dir);
  const auto bad_bbox = run_seqloc({"preprocess", map.string(), "-o", (dir / "r.gpkg").string(), "--bbox", "1,2,3"});
  EXPECT_EQ(bad_bbox.exit_code, 2);
  EXPECT_NE(bad_bbox.err.find("--bbox '1,2,3'"), std::string::npos) << bad_bbox.err;
  const auto bad_shard = run_seqloc({"preprocess", map.string(), "-o", (dir / "r.gpkg").string(), "--shard", "5/2"});
  EXPECT_EQ(bad_shard.exit_code, 2);
  EXPECT_NE(bad_shard.err.find("5/2"), std::string::npos) << bad_shard.err;
  // Values sscanf took (a NaN, an int overflow, trailing garbage in a field) are usage errors.
  for (const auto& [option, value] :
       {std::pair{"--bbox", "1,2,3,nan"}, std::pair{"--bbox", "1,2,3,4x"}, std::pair{"--bbox", "1,,2,3,4"},
        std::pair{"--shard", "99999999999/4"}, std::pair{"--shard", "1/4/2"}}) {
    const auto r = run_seqloc({"preprocess", map.string(), "-o", (dir / "r.gpkg").string(), option, value});
    EXPECT_EQ(r.exit_code, 2) << option << " " << value;
    EXPECT_NE(r.err.find(value), std::string::npos) << r.err;
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "r.gpkg"));
}

TEST(Cli, PreprocessWritesACacheAndInfoDescribesIt) {
  test::ScratchDir dir;
  const auto map = small_map(dir);
  const auto out = dir / "r.gpkg";
  const auto r = run_seqloc({"preprocess", map.string(), "-o", out.string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_EQ(r.err, "") << "no progress bar when stderr is not a terminal";
  EXPECT_NE(r.out.find("wrote " + out.string()), std::string::npos) << r.out;
  EXPECT_TRUE(std::filesystem::exists(out));
  EXPECT_FALSE(std::filesystem::exists(out.string() + ".partial"));

  const auto again = run_seqloc({"preprocess", map.string(), "-o", out.string()});
  EXPECT_EQ(again.exit_code, 2);
  EXPECT_EQ(count_lines(again.err), 1) << again.err;
  EXPECT_NE(again.err.find("already exists; pass --overwrite"), std::string::npos) << again.err;

  const auto info = run_seqloc({"cache", "info", out.string(), "--json"});
  ASSERT_EQ(info.exit_code, 0) << info.err;
  const auto json = nlohmann::json::parse(info.out);
  // Numbers are JSON numbers, equal to what the cache holds.
  EXPECT_EQ(json["format_version"], raster::kCacheFormatVersion);
  const auto metadata = raster::read_cache_metadata(out);
  EXPECT_TRUE(json["centre_lat"].is_number_float());
  EXPECT_EQ(json["centre_lat"].get<double>(), metadata.centre_lat);
  EXPECT_EQ(json["bbox_max_lon"].get<double>(), metadata.bbox.max_lon);
  EXPECT_EQ(json["cell_m"], 0.5);
  EXPECT_EQ(json["tile_px"], 512);
  EXPECT_EQ(json["tile_x0"], metadata.grid.tx0);
  EXPECT_TRUE(json["shard_count"].is_number_integer());
  EXPECT_EQ(json["corridor_m"].get<double>(), metadata.corridor_m) << "every number row, typed where it is written";
  EXPECT_EQ(json["source_sha256"], osm::file_sha256(map));
  EXPECT_EQ(json["source_file"], "map.osm.pbf");
  EXPECT_EQ(json["state"], "complete");
  EXPECT_EQ(json["classes"]["ways"][7], "road");
  const auto text = run_seqloc({"cache", "info", out.string()});
  EXPECT_EQ(text.exit_code, 0);
  EXPECT_NE(text.out.find("max_distance_m"), std::string::npos);
}

TEST(Cli, ProgressOnRequestAndTimestampedLogs) {
  test::ScratchDir dir;
  const auto map = small_map(dir);
  const auto r = run_seqloc({"-v", "preprocess", map.string(), "-o", (dir / "r.gpkg").string(), "--progress",
                             "--report", (dir / "report.json").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  EXPECT_NE(r.err.find("tiles ["), std::string::npos) << r.err;
  EXPECT_NE(r.err.find("] preprocess "), std::string::npos) << "a timestamped log line: " << r.err;
  const auto report = nlohmann::json::parse(test::read_file(dir / "report.json"));
  EXPECT_EQ(report["tiles_written"], report["tiles_total"]);
  EXPECT_GT(report["tiles_total"].get<int>(), 0);
  // A global option after the subcommand, as osmium and git users type it; and after a nested one.
  const auto after = run_seqloc({"preprocess", map.string(), "-o", (dir / "r2.gpkg").string(), "-v"});
  ASSERT_EQ(after.exit_code, 0) << after.err;
  EXPECT_NE(after.err.find("] preprocess "), std::string::npos) << "a timestamped log line: " << after.err;
  const auto nested = run_seqloc({"cache", "info", (dir / "r2.gpkg").string(), "--verbose"});
  EXPECT_EQ(nested.exit_code, 0) << nested.err;
}

TEST(Cli, DataErrorsExitOneWithOneLine) {
  test::ScratchDir dir;
  const auto missing = run_seqloc({"preprocess", (dir / "nope.osm.pbf").string(), "-o", (dir / "r.gpkg").string()});
  EXPECT_EQ(missing.exit_code, 1);
  EXPECT_EQ(count_lines(missing.err), 1) << missing.err;
  EXPECT_NE(missing.err.find("nope.osm.pbf: no such file"), std::string::npos) << missing.err;
  const auto info = run_seqloc({"cache", "info", (dir / "nope.gpkg").string()});
  EXPECT_EQ(info.exit_code, 1);
  EXPECT_NE(info.err.find("nope.gpkg"), std::string::npos) << info.err;
}

TEST(Cli, ShardsMergeIntoOneCache) {
  test::ScratchDir dir;
  const auto map = small_map(dir);
  std::vector<std::string> merge{"cache", "merge", (dir / "merged.gpkg").string()};
  for (int i = 0; i < 3; ++i) {
    const auto shard = dir / ("s" + std::to_string(i) + ".gpkg");
    const auto r = run_seqloc({"preprocess", map.string(), "-o", shard.string(), "--shard", std::to_string(i) + "/3"});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    merge.push_back(shard.string());
  }
  const auto r = run_seqloc(merge);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  raster::CacheReader merged(dir / "merged.gpkg");
  EXPECT_EQ(merged.metadata().shard_count, 1);
  ASSERT_EQ(run_seqloc({"preprocess", map.string(), "-o", (dir / "single.gpkg").string()}).exit_code, 0);
  raster::CacheReader single(dir / "single.gpkg");
  for (std::int64_t row = 0; row < single.grid().tiles_high(); ++row) {
    for (std::int64_t col = 0; col < single.grid().tiles_wide(); ++col) {
      EXPECT_EQ(merged.tile_blob(raster::Layer::road_distance, col, row),
                single.tile_blob(raster::Layer::road_distance, col, row));
      EXPECT_EQ(merged.tile_blob(raster::Layer::classes, col, row), single.tile_blob(raster::Layer::classes, col, row));
    }
  }
}

}  // namespace
}  // namespace seqloc
