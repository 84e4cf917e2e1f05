// bench/calibrate: fits the built-in matcher's temperature, blur and floor (calibration.hpp) by
// the mean NLL of the true cell over development routes, and prints the fit, the NLL of the
// current defaults and of a uniform volume, and one line of JSON.
//   bench_calibrate --cache A.gpkg ROUTE... [--cache B.gpkg ROUTE...]
// Routes are observation routes with ground truth (seqloc simulate). Use seeds that no report uses.

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <string>
#include <vector>

#include "seqloc/pipeline/calibration.hpp"
#include "seqloc/pipeline/localize.hpp"

namespace pl = seqloc::pipeline;

int main(int argc, char** argv) {
  std::vector<std::pair<std::string, std::vector<std::string>>> sets;
  for (int i = 1; i < argc; ++i) {
    const std::string a = argv[i];
    if (a == "--cache" && i + 1 < argc) {
      sets.emplace_back(argv[++i], std::vector<std::string>{});
    } else if (!sets.empty()) {
      sets.back().second.push_back(a);
    } else {
      std::fprintf(stderr, "usage: bench_calibrate --cache CACHE ROUTE... [--cache CACHE ROUTE...]\n");
      return 2;
    }
  }
  const pl::MatcherConfig defaults;
  pl::MatcherConfig raw = defaults;
  raw.temperature = 1;  // the fit scales the raw scores itself
  raw.calibration = {};
  raw.threads = 2;
  const pl::BevMatcher matcher(raw);
  pl::CalibrationFit fit;
  auto grid = fit.grid();
  // The current defaults must be on the grid to be compared.
  if (std::find(grid.temperatures.begin(), grid.temperatures.end(), defaults.temperature) == grid.temperatures.end()) {
    grid.temperatures.push_back(defaults.temperature);
    fit = pl::CalibrationFit(grid);
  }
  const int size = raw.size, bins = raw.headings;
  std::size_t frames = 0;
  for (const auto& [cache_path, routes] : sets) {
    seqloc::raster::CacheReader cache(cache_path);
    const auto projection = cache.metadata().projection();
    for (const auto& dir : routes) {
      const auto route = pl::read_route(dir);
      for (const auto& f : route.frames) {
        if (!f.truth || !f.truth->heading_deg || f.observation.empty()) continue;
        const auto scores = pl::match_frame(f, cache, matcher);
        const pl::GridCrop crop = pl::frame_crop(f, cache.grid(), projection);
        double gamma = 0;
        const auto truth = projection.forward(f.truth->where, gamma);
        const double grid_heading = *f.truth->heading_deg - gamma;
        const auto u = static_cast<int>(std::lround((truth.x_m - crop.x) / 0.5 + (size - 1) / 2.0));
        const auto v = static_cast<int>(std::lround(-(truth.y_m - crop.y) / 0.5 + (size - 1) / 2.0));
        const int b = static_cast<int>(((std::lround(grid_heading * bins / 360.0) % bins) + bins) % bins);
        fit.add(scores, size, size, bins, v, u, b);
        ++frames;
      }
      std::fprintf(stderr, "calibrate: %s, %zu frames so far\n", dir.c_str(), frames);
    }
  }
  const auto best = fit.best();
  const double current = fit.mean_nll(defaults.temperature, defaults.calibration);
  std::printf("frames %zu (true cell outside the crop: %zu)\n", best.frames, best.skipped);
  std::printf("uniform volume:            NLL %.3f nats\n", best.uniform_nll);
  std::printf("current defaults (T %.3g): NLL %.3f nats, gain over uniform %+.3f\n", defaults.temperature, current,
              best.uniform_nll - current);
  std::printf("fit: T %.3g, blur %.3g cells, %.3g bins, floor %.3g: NLL %.3f nats, gain over uniform %+.3f\n",
              best.temperature, best.calibration.blur_cells, best.calibration.blur_bins, best.calibration.floor,
              best.nll, best.uniform_nll - best.nll);
  // The neighbourhood of the fit, one parameter at a time.
  for (double t : fit.grid().temperatures) {
    std::printf("  T %-5.3g NLL %.3f\n", t, fit.mean_nll(t, best.calibration));
  }
  std::printf(
      "{\"frames\": %zu, \"skipped\": %zu, \"uniform_nll\": %.4f, \"current_nll\": %.4f, \"temperature\": %.4g, "
      "\"blur_cells\": %.4g, \"blur_bins\": %.4g, \"floor\": %.4g, \"nll\": %.4f}\n",
      best.frames, best.skipped, best.uniform_nll, current, best.temperature, best.calibration.blur_cells,
      best.calibration.blur_bins, best.calibration.floor, best.nll);
  return 0;
}
