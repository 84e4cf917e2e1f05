// The preprocess report's one writer and one reader (io/preprocess_report.hpp): every field round
// trips with a distinct value, the derived megapixels are what the tiles make, and each thing wrong
// in a file is one clear error naming the file and the field.

#include <fstream>
#include <string>

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include "seqloc/core/error.hpp"
#include "seqloc/io/preprocess_report.hpp"
#include "support/test_support.hpp"

namespace seqloc::io {
namespace {

void write_text(const std::filesystem::path& path, const std::string& text) { std::ofstream(path) << text; }

std::string report_refusal(const std::filesystem::path& path) {
  try {
    (void)read_preprocess_report(path);
  } catch (const DataError& e) {
    return e.what();
  }
  return "";
}

// Every field a value no other field has, so that two fields swapped by the writer or the reader
// show.
PreprocessReport distinct() {
  PreprocessReport r;
  r.output = "/tmp/region.gpkg";
  r.corridor_m = 37.5;
  r.tiles_total = 101;
  r.tiles_written = 102;
  r.tiles_resumed = 103;
  r.tiles_skipped = 104;
  r.tiles_wide = 105;
  r.tiles_high = 106;
  r.nodes = 107;
  r.lines = 108;
  r.areas = 109;
  r.roads = 110;
  r.ways_missing_nodes = 111;
  r.multipolygon_open_chains = 112;
  r.read_seconds = 1.25;
  r.render_seconds = 2.5;
  r.total_seconds = 3.75;
  r.classes_cpu_seconds = 4.125;
  r.distance_cpu_seconds = 5.25;
  r.encode_cpu_seconds = 6.375;
  r.write_seconds = 7.5;
  r.threads = 8;
  r.start_mb = 9.25;
  r.read_peak_mb = 10.5;
  r.render_peak_mb = 11.75;
  r.render_start_mb = 12.125;
  r.spilled_bytes = 5'000'000'000ULL;  // past 32 bits
  r.scale_error = 3.5e-4;
  r.bbox = {1.25, 42.5, 1.75, 42.625};
  r.centre_lat = 42.5625;
  r.centre_lon = 1.5;
  return r;
}

TEST(PreprocessReport, EveryFieldRoundTrips) {
  test::ScratchDir dir;
  const PreprocessReport r = distinct();
  write_text(dir / "report.json", preprocess_report_json(r));
  const PreprocessReport b = read_preprocess_report(dir / "report.json");
  EXPECT_EQ(b.output, r.output);
  EXPECT_EQ(b.corridor_m, r.corridor_m);
  EXPECT_EQ(b.tiles_total, r.tiles_total);
  EXPECT_EQ(b.tiles_written, r.tiles_written);
  EXPECT_EQ(b.tiles_resumed, r.tiles_resumed);
  EXPECT_EQ(b.tiles_skipped, r.tiles_skipped);
  EXPECT_EQ(b.tiles_wide, r.tiles_wide);
  EXPECT_EQ(b.tiles_high, r.tiles_high);
  EXPECT_EQ(b.nodes, r.nodes);
  EXPECT_EQ(b.lines, r.lines);
  EXPECT_EQ(b.areas, r.areas);
  EXPECT_EQ(b.roads, r.roads);
  EXPECT_EQ(b.ways_missing_nodes, r.ways_missing_nodes);
  EXPECT_EQ(b.multipolygon_open_chains, r.multipolygon_open_chains);
  EXPECT_EQ(b.read_seconds, r.read_seconds);
  EXPECT_EQ(b.render_seconds, r.render_seconds);
  EXPECT_EQ(b.total_seconds, r.total_seconds);
  EXPECT_EQ(b.classes_cpu_seconds, r.classes_cpu_seconds);
  EXPECT_EQ(b.distance_cpu_seconds, r.distance_cpu_seconds);
  EXPECT_EQ(b.encode_cpu_seconds, r.encode_cpu_seconds);
  EXPECT_EQ(b.write_seconds, r.write_seconds);
  EXPECT_EQ(b.threads, r.threads);
  EXPECT_EQ(b.start_mb, r.start_mb);
  EXPECT_EQ(b.read_peak_mb, r.read_peak_mb);
  EXPECT_EQ(b.render_peak_mb, r.render_peak_mb);
  EXPECT_EQ(b.render_start_mb, r.render_start_mb);
  EXPECT_EQ(b.spilled_bytes, r.spilled_bytes);
  EXPECT_EQ(b.scale_error, r.scale_error);
  EXPECT_EQ(b.bbox.min_lon, r.bbox.min_lon);
  EXPECT_EQ(b.bbox.min_lat, r.bbox.min_lat);
  EXPECT_EQ(b.bbox.max_lon, r.bbox.max_lon);
  EXPECT_EQ(b.bbox.max_lat, r.bbox.max_lat);
  EXPECT_EQ(b.centre_lat, r.centre_lat);
  EXPECT_EQ(b.centre_lon, r.centre_lon);
}

TEST(PreprocessReport, TheFileHoldsTheKeysTheBenchmarkReadsAndTheDerivedMegapixels) {
  // bench/preprocess/run reads these keys with Python's json; the megapixels of one layer are the
  // shard's tiles of 512 x 512 pixels.
  const auto j = nlohmann::json::parse(preprocess_report_json(distinct()));
  EXPECT_EQ(j.at("megapixels_per_layer").get<double>(), 101 * 512.0 * 512.0 / 1e6);
  EXPECT_EQ(j.at("features").at("roads").get<int>(), 110);
  for (const char* key : {"tiles_total", "total_seconds", "render_peak_mb", "encode_cpu_seconds", "threads"}) {
    EXPECT_TRUE(j.contains(key)) << key;
  }
}

TEST(PreprocessReport, EachThingWrongIsOneErrorNamingTheFileAndTheField) {
  test::ScratchDir dir;
  const auto path = dir / "report.json";
  const auto good = nlohmann::json::parse(preprocess_report_json(distinct()));
  auto with = [&](const char* key, const nlohmann::json& value) {
    nlohmann::json j = good;
    if (value.is_null()) {
      j.erase(key);
    } else {
      j[key] = value;
    }
    write_text(path, j.dump());
    return report_refusal(path);
  };
  EXPECT_EQ(report_refusal(path), path.string() + ": cannot read");
  write_text(path, "{\"format\": ");
  EXPECT_NE(report_refusal(path).find(": not JSON"), std::string::npos) << report_refusal(path);
  EXPECT_NE(with("format", "seqloc-calibration").find("not a preprocess report"), std::string::npos);
  EXPECT_NE(with("version", 2).find("version 2, this seqloc reads version 1"), std::string::npos);
  EXPECT_EQ(with("tiles_total", nullptr), path.string() + ": 'tiles_total' must be a whole number");
  EXPECT_EQ(with("tiles_total", 1.5), path.string() + ": 'tiles_total' must be a whole number");
  EXPECT_EQ(with("spilled_bytes", -1), path.string() + ": 'spilled_bytes' must be a whole number");
  EXPECT_EQ(with("total_seconds", "3"), path.string() + ": 'total_seconds' must be a number");
  EXPECT_EQ(with("output", 3), path.string() + ": 'output' must be a string");
  EXPECT_EQ(with("bbox", nlohmann::json::array({1, 2, 3})), path.string() + ": 'bbox' must be an array of 4 numbers");
  nlohmann::json j = good;
  j["features"].erase("roads");
  write_text(path, j.dump());
  EXPECT_EQ(report_refusal(path), path.string() + ": features: 'roads' must be a whole number");
  write_text(path, preprocess_report_json(distinct()));
  EXPECT_EQ(report_refusal(path), "");
}

}  // namespace
}  // namespace seqloc::io
