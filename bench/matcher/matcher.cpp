// bench/matcher: frames per second of the built-in matcher for a 128 x 128 x 256 volume from
// observations rendered on a real region (north-Bayreuth, 20 m panorama, default noise), with 1
// and 2 threads; the peer is one forward + one inverse 2-D FFT of the same size, times 256 headings
// (the cost a matcher would pay with a single channel and no quarter-turn reuse).
//   bench_matcher CACHE.gpkg

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <string>
#include <vector>

#include <opencv2/core.hpp>

#include "seqloc/core/angles.hpp"
#include "seqloc/matcher/matcher.hpp"
#include "seqloc/sim/simulate.hpp"

namespace core = seqloc::core;
namespace io = seqloc::io;
namespace matcher = seqloc::matcher;
namespace sim = seqloc::sim;
namespace raster = seqloc::raster;
using Clock = std::chrono::steady_clock;

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: bench_matcher CACHE.gpkg\n");
    return 2;
  }
  raster::CacheReader cache(argv[1], 256);
  const auto roads = cache.roads();
  // Observations at 16 points of the road network, headings along the road.
  sim::ObservationModel camera;
  std::vector<io::Observation> observations;
  std::vector<std::vector<std::uint8_t>> maps;
  matcher::MatcherConfig config;
  std::size_t codes = 0, templates = 0;
  for (std::size_t r = 0; r < roads.size() && observations.size() < 16; r += std::max<std::size_t>(1, roads.size() / 16)) {
    const auto& pts = roads[r].points;
    if (pts.size() < 2) continue;
    const auto& a = pts[0];
    const auto& b = pts[1];
    const sim::GridPose pose{a.x_m, a.y_m, std::atan2(b.x_m - a.x_m, b.y_m - a.y_m) * core::kRadToDeg};
    observations.push_back(sim::render_observation(cache, pose, camera));
    // The matcher transforms one template for the visible disc and one per code beyond the first
    // of each channel (matcher.cpp), per heading in a quarter turn.
    const auto observed = matcher::BevMatcher::observed_codes(observations.back());
    codes += observed.size();
    for (std::size_t o = 0; o < observed.size(); ++o) templates += o == 0 || observed[o - 1][0] == observed[o][0];
    const int side = config.size + observations.back().size - 1;
    const auto u = std::llround(cache.grid().region_u(a.x_m) + 0.5), v = std::llround(cache.grid().region_v(a.y_m) + 0.5);
    maps.emplace_back();
    cache.read_classes(u - side / 2, v - side / 2, side, side, maps.back(), true);
  }
  const double mean_codes = static_cast<double>(codes) / static_cast<double>(observations.size());
  const double mean_templates = static_cast<double>(templates) / static_cast<double>(observations.size());
  std::printf("%zu observations of %d x %d cells, %.1f observed codes (channels) on average, %.1f templates per heading\n",
              observations.size(), observations[0].size, observations[0].size, mean_codes, mean_templates);

  double fps[2] = {};
  for (int threads : {1, 2}) {
    config.threads = threads;
    const matcher::BevMatcher matcher(config);
    (void)matcher.match(observations[0], maps[0]);  // warm-up
    const auto t0 = Clock::now();
    for (std::size_t i = 0; i < observations.size(); ++i) (void)matcher.match(observations[i], maps[i]);
    const double s = std::chrono::duration<double>(Clock::now() - t0).count() / static_cast<double>(observations.size());
    fps[threads - 1] = 1.0 / s;
    std::printf("128x128x256 volume, %d thread%s: %.1f ms/frame, %.2f frames/s\n", threads, threads > 1 ? "s" : "",
                s * 1000, 1.0 / s);
  }
  // The calibration localize applies to each volume (calibration.hpp), on real volumes.
  config.threads = 1;
  std::vector<std::vector<float>> volumes;
  {
    const matcher::BevMatcher matcher(config);
    for (std::size_t i = 0; i < observations.size(); ++i) volumes.push_back(matcher.match(observations[i], maps[i]));
  }
  double calibration_ms[2] = {};
  for (int threads : {1, 2}) {
    auto copies = volumes;
    const auto c0 = Clock::now();
    for (auto& volume : copies) {
      matcher::calibrate_volume(volume, config.size, config.size, config.headings, config.calibration, threads);
    }
    calibration_ms[threads - 1] =
        std::chrono::duration<double, std::milli>(Clock::now() - c0).count() / static_cast<double>(copies.size());
    std::printf("calibration (blur %g cells, %g bins, floor %g), %d thread%s: %.1f ms/frame, %.2f of the matcher's "
                "time with as many threads\n",
                config.calibration.blur_cells, config.calibration.blur_bins, config.calibration.floor, threads,
                threads > 1 ? "s" : "", calibration_ms[threads - 1], calibration_ms[threads - 1] * fps[threads - 1] / 1000.0);
  }
  // Peer: 256 single-channel correlations by FFT (forward + inverse) of the same size, 1 thread.
  const int n = cv::getOptimalDFTSize(config.size + observations[0].size - 1);
  cv::Mat a(n, n, CV_32F), f, back;
  cv::randu(a, 0, 1);
  const auto t0 = Clock::now();
  for (int k = 0; k < 256; ++k) {
    cv::dft(a, f);
    cv::dft(f, back, cv::DFT_INVERSE | cv::DFT_REAL_OUTPUT);
  }
  const double peer_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count();
  std::printf("peer: 256 forward + inverse FFTs of %d x %d, 1 thread: %.1f ms; matcher (1 thread) / peer = %.2f\n", n, n,
              peer_ms, 1000.0 / fps[0] / peer_ms);
  std::printf("{\"benchmark\": \"matcher\", \"volume\": \"128x128x256\", \"observation\": %d, \"mean_channels\": %.1f, "
              "\"mean_templates\": %.1f, \"fps_1_thread\": %.2f, \"fps_2_threads\": %.2f, \"peer_256_fft_pairs_ms\": %.1f, \"ratio_to_peer\": %.2f, "
              "\"calibration_ms_1_thread\": %.1f, \"calibration_ms_2_threads\": %.1f}\n",
              observations[0].size, mean_codes, mean_templates, fps[0], fps[1], peer_ms, 1000.0 / fps[0] / peer_ms, calibration_ms[0],
              calibration_ms[1]);
  return 0;
}
