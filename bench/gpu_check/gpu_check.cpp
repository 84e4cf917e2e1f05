// gpu_check: the CUDA backend against the CPU filter on real routes (scripts/gpu-check runs it on
// the GPU machine; ctest runs it with --device cuda-host on a short route). The sample region is
// preprocessed and routes are simulated along its roads, their frames scored by the built-in
// matcher; each route is stepped frame by frame by two SequentialLocalizers in lockstep, one on
// the CPU and one on the device, in the seqloc and the online configuration. Per frame: the poses
// (within one cell, 0.5 m, and one heading bin) and, where both windows sit on the same cells, the
// beliefs (log-probabilities within 1e-3 wherever a cell holds at least 1e-6 of the peak).
// Exit 0 when at least 99.9 % of the frames agree on both counts; ends with one line of JSON.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "seqloc/ingest/preprocess.hpp"
#include "seqloc/io/route.hpp"
#include "seqloc/pipeline/localize.hpp"
#include "seqloc/pipeline/sequential_localizer.hpp"
#include "seqloc/sim/simulate.hpp"

namespace fs = std::filesystem;
namespace pl = seqloc::pipeline;

namespace {

struct Tally {
  int frames = 0, poses_agree = 0, beliefs_compared = 0, beliefs_agree = 0;
  double worst_log_diff = 0, worst_position_m = 0;
};

// The largest |log a - log b| over the cells where `a` holds at least 1e-6 of its peak.
double belief_log_diff(const seqloc::filter::BeliefVolume& a, const seqloc::filter::BeliefVolume& b) {
  const float peak = *std::max_element(a.data(), a.data() + a.size());
  double worst = 0;
  for (std::size_t i = 0; i < a.size(); ++i) {
    if (a.data()[i] < 1e-6f * peak) continue;
    const double d = b.data()[i] > 0 ? std::abs(std::log(a.data()[i]) - std::log(b.data()[i])) : INFINITY;
    worst = std::max(worst, d);
  }
  return worst;
}

void compare_route(const seqloc::io::Route& route, seqloc::raster::CacheReader& cache,
                   const pl::LocalizeOptions& options, bool online, pl::Device device, Tally& tally) {
  pl::SequentialLocalizer cpu(cache, options.filter, online, options.recentre_margin, 0, pl::Device::cpu);
  pl::SequentialLocalizer dev(cache, options.filter, online, options.recentre_margin, 0, device);
  const auto frames = pl::stored_route_frames(route, cache, options);
  const auto projection = cache.metadata().projection();
  const double bin_deg = 360.0 / options.filter.headings;
  for (std::size_t j = 0; j < route.frames.size(); ++j) {
    const auto& f = route.frames[j];
    const auto frame = frames(j);
    const pl::GridCrop crop = pl::frame_crop(f, cache.grid(), projection);
    const auto gps = pl::frame_gps_fix(f, projection);
    const pl::FrameEstimate a = cpu.step(*frame, crop, f.odometry, gps);
    const pl::FrameEstimate b = dev.step(*frame, crop, f.odometry, gps);
    const double d = std::hypot(a.x_m - b.x_m, a.y_m - b.y_m);
    const double dh = std::abs(std::remainder(a.grid_heading_deg - b.grid_heading_deg, 360.0));
    ++tally.frames;
    tally.poses_agree += d <= 0.5 && dh <= bin_deg ? 1 : 0;
    tally.worst_position_m = std::max(tally.worst_position_m, d);
    if (cpu.window().origin_u() != dev.window().origin_u() || cpu.window().origin_v() != dev.window().origin_v())
      continue;  // the windows moved apart: no cell-by-cell comparison
    const double diff = belief_log_diff(cpu.filter()->belief(), dev.filter()->belief());
    ++tally.beliefs_compared;
    tally.beliefs_agree += diff <= 1e-3 ? 1 : 0;
    tally.worst_log_diff = std::max(tally.worst_log_diff, diff);
  }
}

}  // namespace

int main(int argc, char** argv) {
  std::string device_name = "cuda", work_dir = "/tmp/seqloc-gpu-check";
  fs::path sample = fs::path(SEQLOC_SOURCE_DIR) / "samples/rural-valley.osm.pbf";
  int routes = 4, frames = 60, window = 256;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i], v = argv[i + 1];
    if (a == "--device") {
      device_name = v;
    } else if (a == "--routes") {
      routes = std::stoi(v);
    } else if (a == "--frames") {
      frames = std::stoi(v);
    } else if (a == "--window") {
      window = std::stoi(v);
    } else if (a == "--work") {
      work_dir = v;
    } else if (a == "--sample") {
      sample = v;
    } else {
      argc = -1;
    }
  }
  const auto device = pl::device_from_name(device_name);
  if (argc < 0 || argc % 2 == 0 || !device || *device == pl::Device::cpu) {
    std::fprintf(stderr,
                 "usage: gpu_check [--device cuda|cuda-host] [--routes 4] [--frames 60] [--window 256] "
                 "[--work DIR] [--sample OSM_PBF]\n");
    return 2;
  }
  pl::LocalizeOptions options;
  options.filter.width = options.filter.height = window;
  try {
    pl::check_device(*device, options.filter);
  } catch (const std::exception& e) {
    std::printf("gpu_check: %s\n{\"check\": \"gpu_real_routes\", \"measured\": false}\n", e.what());
    return 1;
  }
  const fs::path work = work_dir;
  fs::remove_all(work);
  fs::create_directories(work);
  seqloc::ingest::PreprocessOptions pre;
  pre.input = sample;
  pre.output = work / "sample.gpkg";
  seqloc::ingest::preprocess_region(pre);
  seqloc::raster::CacheReader cache(pre.output, 256);
  seqloc::sim::SimulateOptions sim;
  sim.routes = routes;
  sim.frames = frames;
  sim.seed = 5;
  seqloc::sim::simulate_routes(cache, sim, work / "routes");
  Tally tally;
  for (int r = 0; r < routes; ++r) {
    char name[32];
    std::snprintf(name, sizeof name, "route_%03d", r);
    const auto route = seqloc::io::read_route(work / "routes" / name);
    for (const bool online : {false, true}) compare_route(route, cache, options, online, *device, tally);
  }
  const double poses = 100.0 * tally.poses_agree / std::max(1, tally.frames);
  const double beliefs = 100.0 * tally.beliefs_agree / std::max(1, tally.beliefs_compared);
  const bool pass = poses >= 99.9 && beliefs >= 99.9;
  std::printf(
      "%s against the CPU on %d routes x %d frames of the sample region (seqloc and online, window %d): poses "
      "within a cell and a bin on %.2f %% of %d frames (worst %.3f m); beliefs within 1e-3 in log where the "
      "mass is on %.2f %% of %d frames compared (worst %.2e): %s\n",
      device_name.c_str(), routes, frames, window, poses, tally.frames, tally.worst_position_m, beliefs,
      tally.beliefs_compared, tally.worst_log_diff, pass ? "PASS" : "FAIL");
  std::printf(
      "{\"check\": \"gpu_real_routes\", \"device\": \"%s\", \"measured\": true, \"frames\": %d, "
      "\"poses_agree_pct\": %.3f, \"beliefs_compared\": %d, \"beliefs_agree_pct\": %.3f, "
      "\"worst_log_diff\": %.3e, \"worst_position_m\": %.4f, \"pass\": %s}\n",
      device_name.c_str(), tally.frames, poses, tally.beliefs_compared, beliefs, tally.worst_log_diff,
      tally.worst_position_m, pass ? "true" : "false");
  fs::remove_all(work);
  return pass ? 0 : 1;
}
