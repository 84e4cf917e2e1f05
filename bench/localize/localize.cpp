// bench/localize: a frame's intake on one thread against its floor (mapping the file and
// converting float16 to float32); then frames/s end to end on a 1,000-frame route of 128x128x256
// float16 volumes with the default 256x256x256 window (seqloc mode), with the split by stage
// (reading and preparing volumes on a background task, the filter, writing the outputs) and peak
// memory; then the same route without self-calibration, with a backbone calibration, and in
// smooth mode (time per frame against seqloc's, peak memory). The volumes are 16 distinct random
// ones cycled along the route (128 MB, so the page cache holds them). --intake: the intake alone.
//
// Then routes of observations (the demo's path): 2 simulated routes x 20 frames of the sample
// region, scored by the built-in matcher, window 192; each mode alone, then all four at once
// (which score each observation once), with frames/s and peak memory for each run.
//
// With --device cuda (or cuda-host) the 1,000-frame route alone, on that device (device_run).

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <functional>
#include <map>
#include <optional>
#include <random>
#include <string>
#include <vector>

#include "seqloc/core/thread_pool.hpp"
#include "seqloc/core/units.hpp"
#include "seqloc/ingest/preprocess.hpp"
#include "seqloc/io/npy.hpp"
#include "seqloc/io/route.hpp"
#include "seqloc/io/run_folder.hpp"
#include "seqloc/matcher/calibration.hpp"
#include "seqloc/osm/synthetic.hpp"
#include "seqloc/pipeline/localize.hpp"
#include "seqloc/pipeline/sequential_localizer.hpp"
#include "seqloc/sim/simulate.hpp"

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

// Peak resident memory since the last reset_peak().
void reset_peak() { std::ofstream("/proc/self/clear_refs") << "5"; }

// Each mode alone and all four together on observation routes: frames/s and peak memory.
std::string observation_routes(const fs::path& work) {
  namespace pl = seqloc::pipeline;
  seqloc::ingest::PreprocessOptions pre;
  pre.input = fs::path(SEQLOC_SOURCE_DIR) / "samples/rural-valley.osm.pbf";
  pre.output = work / "sample.gpkg";
  seqloc::ingest::preprocess_region(pre);
  seqloc::raster::CacheReader cache(pre.output, 256);
  seqloc::sim::SimulateOptions sim;
  sim.routes = 2;
  sim.frames = 20;
  sim.seed = 11;
  seqloc::sim::simulate_routes(cache, sim, work / "routes");
  std::vector<seqloc::io::Route> routes;
  for (const char* name : {"route_000", "route_001"}) routes.push_back(seqloc::io::read_route(work / "routes" / name));
  pl::LocalizeOptions options;
  options.filter.width = options.filter.height = 192;
  options.filter.threads = seqloc::core::default_threads();
  const double frames = 2 * 20;
  auto run = [&](const std::vector<seqloc::io::Mode>& modes, const char* name) {
    reset_peak();
    const auto t0 = Clock::now();
    const auto batch = pl::localize_routes(routes, cache, options, modes);
    const double seconds = std::chrono::duration<double>(Clock::now() - t0).count();
    const double mb = static_cast<double>(peak_kb()) / 1024.0;
    std::printf("  %-8s %6.1f s  %5.2f frames/s per mode  peak %4.0f MB  (%zu volumes made)\n", name, seconds,
                frames / seconds, mb, batch.frames_made);
    return std::pair{seconds, mb};
  };
  std::printf("observation routes: 2 x 20 frames of the sample region, matcher 128x128x256, window 192, %d threads\n",
              options.filter.threads);
  std::map<std::string, std::pair<double, double>> alone;
  double sum = 0;
  for (const auto mode :
       {seqloc::io::Mode::single, seqloc::io::Mode::offline, seqloc::io::Mode::online, seqloc::io::Mode::seqloc}) {
    alone[seqloc::io::mode_name(mode)] = run({mode}, seqloc::io::mode_name(mode));
    sum += alone[seqloc::io::mode_name(mode)].first;
  }
  const auto all = run(
      {seqloc::io::Mode::single, seqloc::io::Mode::offline, seqloc::io::Mode::online, seqloc::io::Mode::seqloc}, "all");
  std::printf("  all four together: %.1f s = %.2f of the four runs alone added up (%.1f s; target <= 0.6)\n", all.first,
              all.first / sum, sum);
  std::string json;
  char field[160];
  for (const auto& [mode, r] : alone) {
    std::snprintf(field, sizeof field, R"(, "obs_%s_frames_per_s": %.2f, "obs_%s_peak_mb": %.0f)", mode.c_str(),
                  frames / r.first, mode.c_str(), r.second);
    json += field;
  }
  std::snprintf(field, sizeof field,
                R"(, "obs_all_s": %.1f, "obs_alone_sum_s": %.1f, "obs_all_over_alone": %.3f, )"
                R"("obs_all_peak_mb": %.0f)",
                all.first, sum, all.first / sum, all.second);
  return json + field;
}

// What a route pays once at each seam between two regions: SequentialLocalizer::hand_over of the
// default window (256 x 256 x 256) between the west and the east half of `pre`'s region, after one
// step near the seam; the mean of 10 hand-overs, back and forth, in ms.
double hand_over_ms(const seqloc::ingest::PreprocessOptions& pre, const seqloc::pipeline::LocalizeOptions& options,
                    const fs::path& work) {
  const seqloc::osm::GeoBox box = *pre.bbox;
  const double seam_lon = (box.min_lon + box.max_lon) / 2;
  auto half = [&](const char* name, double lon0, double lon1) {
    seqloc::ingest::PreprocessOptions o = pre;
    o.output = work / name;
    o.bbox = seqloc::osm::GeoBox{lon0, box.min_lat, lon1, box.max_lat};
    seqloc::ingest::preprocess_region(o);
    return o.output;
  };
  seqloc::raster::CacheReader west(half("west.gpkg", box.min_lon, seam_lon), 256);
  seqloc::raster::CacheReader east(half("east.gpkg", seam_lon, box.max_lon), 256);
  const int h = 128, w = 128, n = 256;
  std::mt19937 rng(5);
  std::normal_distribution<float> noise(0, 2);
  std::vector<float> values(static_cast<std::size_t>(h) * w * n);
  for (auto& v : values) v = noise(rng);
  seqloc::filter::FrameVolume volume;
  volume.data = values.data();
  volume.height = h;
  volume.width = w;
  volume.bins = n;
  const auto frame = seqloc::filter::prepare_frame(volume, options.filter.headings, options.filter.threads);
  seqloc::pipeline::SequentialLocalizer localizer(west, options.filter, /*online=*/false, options.recentre_margin);
  const seqloc::osm::GridPoint near_seam = west.metadata().projection().forward({47.5, seam_lon - 0.0005});
  (void)localizer.step(frame, {near_seam.x_m, near_seam.y_m, 0}, {0, 0, 0}, std::nullopt);
  constexpr int kTimes = 10;
  const auto t0 = Clock::now();
  for (int i = 0; i < kTimes; ++i) localizer.hand_over(i % 2 == 0 ? east : west);
  return 1000.0 * std::chrono::duration<double>(Clock::now() - t0).count() / kTimes;
}

// The backbone calibration the calibrated runs use (a temperature, a blur and a floor).
struct BenchCalibration {
  double temperature;
  seqloc::matcher::VolumeCalibration volume;
};
const BenchCalibration kCalibration{1.5, {1.5, 1.0, 0.05}};

// A frame's intake on one thread against its floor, over the route's distinct volumes (the best of
// five rounds each, ms a frame): the floor maps the .npy file and converts its float16 values to
// float32 in one plain pass into a buffer allocated as a frame is (no transposition, no
// log-softmax); the intake maps it and prepares it as localize does (read, convert, transpose,
// check, normalize), once more tempered by a volume temperature of 2, with a backbone calibration,
// and with its vectors limited to 8 lanes (AVX2, where the CPU has AVX-512).
struct Intake {
  double floor_ms = 0, intake_ms = 0, tempered_ms = 0, calibrated_ms = 0;
  double eight_lanes_ms = 0;  ///< the intake with its vectors limited to 8 lanes (AVX2)
  int lanes = 1;              ///< the intake's vector width here
};

Intake time_intake(const fs::path& dir, int distinct) {
  seqloc::pipeline::LocalizeOptions one;
  one.filter.threads = 1;
  auto tempered = one;
  tempered.volume_temperature = 2;
  auto calibrated = one;
  calibrated.volume_temperature = kCalibration.temperature;
  calibrated.volume_calibration = kCalibration.volume;
  using Work = std::function<void(const seqloc::io::NpyVolume&)>;
  const Work floor = [](const seqloc::io::NpyVolume& npy) {
    const std::size_t n = static_cast<std::size_t>(npy.height()) * npy.width() * npy.bins();
    seqloc::filter::UninitializedAlignedVector<float> floats(n);  // allocated as a prepared frame is
    seqloc::filter::halves_to_floats({static_cast<const std::uint16_t*>(npy.data()), n}, floats);
    if (!(floats[n / 2] > -1e30f)) std::abort();
  };
  auto prepared = [](const seqloc::pipeline::LocalizeOptions& options) -> Work {
    return [options](const seqloc::io::NpyVolume& npy) {
      const auto frame = seqloc::pipeline::prepare_volume(
          npy.view(seqloc::filter::VolumeValues::log_prob, seqloc::core::kCellM), options);
      if (!(frame.entropy >= 0)) std::abort();
    };
  };
  const Work eight_lanes = [plain = prepared(one)](const seqloc::io::NpyVolume& npy) {
    const int before = seqloc::filter::limit_intake_vector_lanes(8);
    plain(npy);
    (void)seqloc::filter::limit_intake_vector_lanes(before);
  };
  const std::vector<Work> works{floor, prepared(one), prepared(tempered), prepared(calibrated), eight_lanes};
  // Rounds over every kind of work, each over all the files in turn, so that a file is not still
  // in the processor's caches from its last round (16 volumes of 8 MB, each made into 16 MB) and
  // every kind sees the machine as the others do (the first round after the volumes were written
  // runs slower): each file's best round.
  std::vector<std::vector<double>> best(works.size(), std::vector<double>(static_cast<std::size_t>(distinct), 1e300));
  for (int round = 0; round < 5; ++round) {
    for (std::size_t w = 0; w < works.size(); ++w) {
      for (int k = 0; k < distinct; ++k) {
        const auto t0 = Clock::now();
        const seqloc::io::NpyVolume npy(dir / ("v" + std::to_string(k) + ".npy"));
        works[w](npy);
        auto& b = best[w][static_cast<std::size_t>(k)];
        b = std::min(b, std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
      }
    }
  }
  auto mean = [&](std::size_t w) {
    double sum = 0;
    for (const double b : best[w]) sum += b;
    return sum / distinct;
  };
  return {mean(0), mean(1), mean(2), mean(3), mean(4), seqloc::filter::intake_vector_lanes()};
}

}  // namespace

// --device cuda|cuda-host: the 1,000-frame route in seqloc and smooth with the forward filter on
// that device, and seqloc once more on the CPU for the share of frames whose poses agree (within
// a cell, 0.5 m, and a heading bin). Returns the JSON line.
std::string device_run(const seqloc::io::Route& route, seqloc::raster::CacheReader& cache,
                       const seqloc::pipeline::LocalizeOptions& cpu_options, seqloc::pipeline::Device device) {
  namespace pl = seqloc::pipeline;
  auto options = cpu_options;
  options.device = device;
  pl::check_device(device, options.filter);
  const double frames = static_cast<double>(route.frames.size());
  auto timed = [&](const pl::LocalizeOptions& o, seqloc::io::Mode mode, double& seconds) {
    const auto t0 = Clock::now();
    auto result = pl::localize_route(route, cache, o, mode);
    seconds = std::chrono::duration<double>(Clock::now() - t0).count();
    return result;
  };
  double seqloc_s = 0, smooth_s = 0, cpu_s = 0;
  const auto on_device = timed(options, seqloc::io::Mode::seqloc, seqloc_s);
  const auto smooth = timed(options, seqloc::io::Mode::smooth, smooth_s);
  const auto on_cpu = timed(cpu_options, seqloc::io::Mode::seqloc, cpu_s);
  std::size_t agree = 0;
  const double bin_deg = 360.0 / options.filter.headings;
  for (std::size_t i = 0; i < on_cpu.poses.size(); ++i) {
    const auto& a = on_cpu.poses[i];
    const auto& b = on_device.poses[i];
    const double d = std::hypot(a.x_m - b.x_m, a.y_m - b.y_m);
    const double dh = std::abs(std::remainder(a.grid_heading_deg - b.grid_heading_deg, 360.0));
    agree += d <= 0.5 && dh <= bin_deg ? 1 : 0;
  }
  const double share = 100.0 * static_cast<double>(agree) / frames;
  std::printf(
      "--device %s: seqloc %.1f frames/s (filter %.1f s, read+prepare %.1f s, waiting for volumes %.1f s); "
      "smooth %.1f frames/s; the CPU's seqloc %.1f frames/s; poses within a cell and a bin of the CPU's: "
      "%.2f %% of %zu frames\n",
      pl::device_name(device), frames / seqloc_s, on_device.filter_seconds, on_device.prepare_seconds,
      on_device.wait_seconds, frames / smooth_s, frames / cpu_s, share, on_cpu.poses.size());
  char json[512];
  std::snprintf(json, sizeof json,
                "{\"benchmark\": \"localize_device\", \"device\": \"%s\", \"frames\": %.0f, \"frames_per_s\": %.2f, "
                "\"filter_s\": %.2f, \"prepare_s\": %.2f, \"wait_s\": %.2f, \"smooth_frames_per_s\": %.2f, "
                "\"cpu_frames_per_s\": %.2f, \"poses_agreeing_pct\": %.2f}",
                pl::device_name(device), frames, frames / seqloc_s, on_device.filter_seconds, on_device.prepare_seconds,
                on_device.wait_seconds, frames / smooth_s, frames / cpu_s, share);
  return json;
}

int main(int argc, char** argv) {
  std::optional<seqloc::pipeline::Device> device;
  if (argc == 3 && std::string(argv[1]) == "--device") device = seqloc::pipeline::device_from_name(argv[2]);
  const bool intake_only = argc == 2 && std::string(argv[1]) == "--intake";
  if (argc != 1 && !intake_only && (!device || *device == seqloc::pipeline::Device::cpu)) {
    std::fprintf(stderr, "usage: bench_localize [--device cuda|cuda-host | --intake]\n");
    return 2;
  }
  if (device) {
    try {
      seqloc::pipeline::check_device(*device, {});
    } catch (const std::exception& e) {
      std::printf("bench localize: %s\n{\"benchmark\": \"localize_device\", \"measured\": false}\n", e.what());
      return 1;
    }
  }
  const fs::path work = "/tmp/seqloc-bench-localize";
  fs::remove_all(work);
  fs::create_directories(work / "route");
  // A region with a 6 km road.
  seqloc::osm::SyntheticMap map(47.5, 10.5);
  map.way({{-3000, 0.25}, {3000, 0.25}}, {{"highway", "secondary"}});
  map.write(work / "map.osm.pbf");
  seqloc::ingest::PreprocessOptions pre;
  pre.input = work / "map.osm.pbf";
  pre.output = work / "region.gpkg";
  pre.bbox = seqloc::osm::GeoBox{10.5 - 0.042, 47.5 - 0.002, 10.5 + 0.042, 47.5 + 0.002};
  seqloc::ingest::preprocess_region(pre);

  const int h = 128, w = 128, n = 256, distinct = 16, frames = 1000;
  std::mt19937 rng(3);
  std::normal_distribution<float> noise(0, 2);
  for (int k = 0; k < distinct; ++k) {
    std::vector<std::uint16_t> values(static_cast<std::size_t>(h) * w * n);
    for (auto& v : values) v = seqloc::filter::float_to_half(std::max(-8.0f, std::min(8.0f, noise(rng))));
    std::ofstream(work / "route" / ("v" + std::to_string(k) + ".npy"), std::ios::binary)
        << seqloc::io::encode_npy_float16(h, w, n, values.data());
  }
  {
    seqloc::io::Route written;
    written.name = "bench";
    for (int t = 0; t < frames; ++t) {
      seqloc::io::RouteFrame f;
      f.frame = std::to_string(t);
      f.timestamp_s = t * 0.5;
      f.volume = work / "route" / ("v" + std::to_string(t % distinct) + ".npy");
      f.crop_grid = seqloc::osm::GridPoint{-2500.0 + 5.0 * t, 0.25};
      f.odometry = {t ? 5.0 : 0.0, 0, 0};
      written.frames.push_back(std::move(f));
    }
    seqloc::io::write_route(written, work / "route");
  }
  const auto route = seqloc::io::read_route(work / "route");
  seqloc::raster::CacheReader cache(pre.output, 256);
  seqloc::pipeline::LocalizeOptions options;
  options.filter.threads = seqloc::core::default_threads();
  if (device) {
    std::printf("1000 frames, 128x128x256 float16 volumes, 256x256x256 window, %d threads\n", options.filter.threads);
    std::printf("%s\n", device_run(route, cache, options, *device).c_str());
    fs::remove_all(work);
    return 0;
  }
  const Intake intake = time_intake(work / "route", distinct);
  std::printf(
      "intake of one frame, 1 thread, %d-lane vectors: %.2f ms (tempered: %.2f ms; calibrated: %.1f ms; 8 lanes: "
      "%.2f ms) against a floor of %.2f ms (map the file, float16 to float32): %.2fx (target <= 3)\n",
      intake.lanes, intake.intake_ms, intake.tempered_ms, intake.calibrated_ms, intake.eight_lanes_ms, intake.floor_ms,
      intake.intake_ms / intake.floor_ms);
  if (intake_only) {
    std::printf(
        "{\"benchmark\": \"localize_intake\", \"intake_ms_per_frame\": %.2f, "
        "\"intake_tempered_ms_per_frame\": %.2f, \"intake_calibrated_ms_per_frame\": %.2f, "
        "\"intake_floor_ms\": %.2f, \"intake_over_floor\": %.2f, \"intake_lanes\": %d, "
        "\"intake_8_lanes_ms_per_frame\": %.2f}\n",
        intake.intake_ms, intake.tempered_ms, intake.calibrated_ms, intake.floor_ms, intake.intake_ms / intake.floor_ms,
        intake.lanes, intake.eight_lanes_ms);
    fs::remove_all(work);
    return 0;
  }
  const auto t0 = Clock::now();
  const auto result = seqloc::pipeline::localize_route(route, cache, options, seqloc::io::Mode::seqloc);
  const double run_s = std::chrono::duration<double>(Clock::now() - t0).count();
  const auto t1 = Clock::now();
  fs::create_directories(work / "out");
  seqloc::io::write_route_outputs(work / "out", result);
  const double write_s = std::chrono::duration<double>(Clock::now() - t1).count();
  const double total = run_s + write_s;
  std::printf("1000 frames, 128x128x256 float16 volumes, 256x256x256 window, %d threads\n", options.filter.threads);
  std::printf("end to end %.1f s = %.1f frames/s (target >= 10)\n", total, frames / total);
  std::printf(
      "stages: read+prepare %.1f s (background, overlapping the filter), filter %.1f s, waiting for the next "
      "volume %.1f s, writing outputs %.2f s; %d window re-centres\n",
      result.prepare_seconds, result.filter_seconds, result.wait_seconds, write_s, result.recentres);
  std::printf("peak memory %.0f MB\n", static_cast<double>(peak_kb()) / 1024.0);
  const double peak_mb = static_cast<double>(peak_kb()) / 1024.0;
  // The same route without self-calibration: what it costs per frame.
  auto plain = options;
  plain.filter.self_calibrate = false;
  const auto t2 = Clock::now();
  const auto without = seqloc::pipeline::localize_route(route, cache, plain, seqloc::io::Mode::seqloc);
  const double plain_s = std::chrono::duration<double>(Clock::now() - t2).count();
  std::printf(
      "without self-calibration: %.1f s = %.1f frames/s, filter %.1f s, waiting for volumes %.1f s "
      "(self-calibration adds %.1f ms a frame to the filter)\n",
      plain_s, frames / plain_s, without.filter_seconds, without.wait_seconds,
      1000.0 * (result.filter_seconds - without.filter_seconds) / frames);
  // The same route with a backbone calibration (temperature, blur and floor, as a calibration.json
  // gives them): the frames calibrated on their way in.
  auto calibrated = options;
  calibrated.volume_temperature = kCalibration.temperature;
  calibrated.volume_calibration = kCalibration.volume;
  const auto t4 = Clock::now();
  const auto with_calibration = seqloc::pipeline::localize_route(route, cache, calibrated, seqloc::io::Mode::seqloc);
  const double calibrated_s = std::chrono::duration<double>(Clock::now() - t4).count();
  std::printf(
      "with a backbone calibration (temperature %.1f, blur %.1f cells and %.1f bins, floor %.2f): %.1f s = %.1f "
      "frames/s, read+prepare %.1f s, filter %.1f s, waiting for volumes %.1f s\n",
      kCalibration.temperature, kCalibration.volume.blur_cells, kCalibration.volume.blur_bins,
      kCalibration.volume.floor, calibrated_s, frames / calibrated_s, with_calibration.prepare_seconds,
      with_calibration.filter_seconds, with_calibration.wait_seconds);
  // Smooth on the same route: its time per frame against seqloc's (issue target: at most 3x) and
  // its own peak memory (target: under 2 GB).
  reset_peak();
  const auto t3 = Clock::now();
  const auto smooth = seqloc::pipeline::localize_route(route, cache, options, seqloc::io::Mode::smooth);
  const double smooth_s = std::chrono::duration<double>(Clock::now() - t3).count();
  const double smooth_peak_mb = static_cast<double>(peak_kb()) / 1024.0;
  std::printf(
      "smooth: %.1f s = %.1f frames/s, %.2fx seqloc's time per frame (target <= 2); filter %.1f s, "
      "read+prepare %.1f s (every volume read twice); peak memory %.0f MB (target < 2048)\n",
      smooth_s, frames / smooth_s, smooth_s / run_s, smooth.filter_seconds, smooth.prepare_seconds, smooth_peak_mb);
  const double hand_over = hand_over_ms(pre, options, work);
  std::printf("hand-over at a seam between two regions: %.0f ms once per crossing (%.1f frames' filter time)\n",
              hand_over, hand_over / (1000.0 * result.filter_seconds / frames));
  const std::string observations = observation_routes(work);
  std::printf(
      "{\"benchmark\": \"localize\", \"frames\": %d, \"frames_per_s\": %.2f, \"total_s\": %.2f, "
      "\"prepare_s\": %.2f, \"filter_s\": %.2f, \"wait_s\": %.2f, \"write_s\": %.3f, \"peak_mb\": %.0f, "
      "\"no_self_calibration_frames_per_s\": %.2f, \"no_self_calibration_filter_s\": %.2f, "
      "\"no_self_calibration_wait_s\": %.2f, \"smooth_frames_per_s\": %.2f, \"smooth_time_ratio_to_seqloc\": %.2f, "
      "\"smooth_peak_mb\": %.0f, "
      "\"hand_over_ms\": %.1f, \"intake_ms_per_frame\": %.2f, \"intake_tempered_ms_per_frame\": %.2f, "
      "\"intake_calibrated_ms_per_frame\": %.2f, \"intake_floor_ms\": %.2f, \"intake_over_floor\": %.2f, "
      "\"intake_lanes\": %d, \"intake_8_lanes_ms_per_frame\": %.2f, "
      "\"calibrated_frames_per_s\": %.2f, \"calibrated_wait_s\": %.2f%s}\n",
      frames, frames / total, total, result.prepare_seconds, result.filter_seconds, result.wait_seconds, write_s,
      peak_mb, frames / plain_s, without.filter_seconds, without.wait_seconds, frames / smooth_s, smooth_s / run_s,
      smooth_peak_mb, hand_over, intake.intake_ms, intake.tempered_ms, intake.calibrated_ms, intake.floor_ms,
      intake.intake_ms / intake.floor_ms, intake.lanes, intake.eight_lanes_ms, frames / calibrated_s,
      with_calibration.wait_seconds, observations.c_str());
  fs::remove_all(work);
  return 0;
}
