// bench/localize: frames/s end to end on a 1,000-frame route of 128x128x256 float16 volumes with
// the default 256x256x256 window (seqloc mode), with the split by stage (reading and preparing
// volumes on a background task, the filter, writing the outputs) and peak memory. The volumes are
// 16 distinct random ones cycled along the route (128 MB, so the page cache holds them).

#include <chrono>
#include <cstdio>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <random>
#include <string>
#include <thread>
#include <vector>

#include "seqloc/osm/synthetic.hpp"
#include "seqloc/pipeline/localize.hpp"
#include "seqloc/pipeline/outputs.hpp"
#include "seqloc/pipeline/preprocess.hpp"

namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

long peak_kb() {
  std::ifstream in("/proc/self/status");
  std::string line;
  while (std::getline(in, line)) {
    if (line.rfind("VmHWM:", 0) == 0) return std::stol(line.substr(6));
  }
  return -1;
}

std::uint16_t to_half(float f) {
  // Values here are in [-8, 8]: normal halves; round to nearest.
  std::uint32_t bits = 0;
  std::memcpy(&bits, &f, 4);
  const std::uint32_t sign = (bits >> 16) & 0x8000u;
  const int exponent = static_cast<int>((bits >> 23) & 0xFF) - 127 + 15;
  if (exponent <= 0) return static_cast<std::uint16_t>(sign);
  const std::uint32_t mantissa = (bits >> 13) & 0x3FF;
  return static_cast<std::uint16_t>(sign | (static_cast<std::uint32_t>(exponent) << 10) | mantissa);
}

}  // namespace

int main() {
  const fs::path work = "/tmp/seqloc-bench-localize";
  fs::remove_all(work);
  fs::create_directories(work / "route");
  // A region with a 6 km road.
  seqloc::osm::SyntheticMap map(47.5, 10.5);
  map.way({{-3000, 0.25}, {3000, 0.25}}, {{"highway", "secondary"}});
  map.write(work / "map.osm.pbf");
  seqloc::pipeline::PreprocessOptions pre;
  pre.input = work / "map.osm.pbf";
  pre.output = work / "region.gpkg";
  pre.bbox = seqloc::osm::GeoBox{10.5 - 0.042, 47.5 - 0.002, 10.5 + 0.042, 47.5 + 0.002};
  seqloc::pipeline::preprocess_region(pre);

  const int h = 128, w = 128, n = 256, distinct = 16, frames = 1000;
  std::mt19937 rng(3);
  std::normal_distribution<float> noise(0, 2);
  for (int k = 0; k < distinct; ++k) {
    std::vector<std::uint16_t> values(static_cast<std::size_t>(h) * w * n);
    for (auto& v : values) v = to_half(std::max(-8.0f, std::min(8.0f, noise(rng))));
    std::string header = "{'descr': '<f2', 'fortran_order': False, 'shape': (128, 128, 256), }";
    while ((10 + header.size() + 1) % 64 != 0) header += ' ';
    header += '\n';
    std::ofstream out(work / "route" / ("v" + std::to_string(k) + ".npy"), std::ios::binary);
    out << "\x93NUMPY" << '\x01' << '\0';
    out.put(static_cast<char>(header.size() & 0xFF)).put(static_cast<char>(header.size() >> 8));
    out << header;
    out.write(reinterpret_cast<const char*>(values.data()), static_cast<std::streamsize>(values.size() * 2));
  }
  std::ofstream(work / "route" / "route.json") << R"({"format": "seqloc-route", "version": 1, "name": "bench"})";
  {
    std::ofstream csv(work / "route" / "frames.csv");
    csv << "frame,timestamp,volume,crop_x,crop_y,odo_forward_m,odo_left_m,odo_yaw_deg\n";
    for (int t = 0; t < frames; ++t) {
      csv << t << "," << t * 0.5 << ",v" << t % distinct << ".npy," << -2500.0 + 5.0 * t << ",0.25,"
          << (t ? 5 : 0) << ",0,0\n";
    }
  }
  const auto route = seqloc::pipeline::read_route(work / "route");
  seqloc::raster::CacheReader cache(pre.output, 256);
  seqloc::pipeline::LocalizeOptions options;
  options.filter.threads = static_cast<int>(std::max(1u, std::thread::hardware_concurrency()));
  const auto t0 = Clock::now();
  const auto result = seqloc::pipeline::localize_route(route, cache, options, seqloc::pipeline::Mode::seqloc);
  const double run_s = std::chrono::duration<double>(Clock::now() - t0).count();
  const auto t1 = Clock::now();
  fs::create_directories(work / "out");
  seqloc::pipeline::write_route_outputs(work / "out", result);
  const double write_s = std::chrono::duration<double>(Clock::now() - t1).count();
  const double total = run_s + write_s;
  std::printf("1000 frames, 128x128x256 float16 volumes, 256x256x256 window, %d threads\n", options.filter.threads);
  std::printf("end to end %.1f s = %.1f frames/s (target >= 10)\n", total, frames / total);
  std::printf("stages: read+prepare %.1f s (background, overlapping the filter), filter %.1f s, waiting for the next "
              "volume %.1f s, writing outputs %.2f s; %d window re-centres\n",
              result.prepare_seconds, result.filter_seconds, result.wait_seconds, write_s, result.recentres);
  std::printf("peak memory %.0f MB\n", static_cast<double>(peak_kb()) / 1024.0);
  std::printf("{\"benchmark\": \"localize\", \"frames\": %d, \"frames_per_s\": %.2f, \"total_s\": %.2f, "
              "\"prepare_s\": %.2f, \"filter_s\": %.2f, \"wait_s\": %.2f, \"write_s\": %.3f, \"peak_mb\": %.0f}\n",
              frames, frames / total, total, result.prepare_seconds, result.filter_seconds, result.wait_seconds,
              write_s, static_cast<double>(peak_kb()) / 1024.0);
  fs::remove_all(work);
  return 0;
}
