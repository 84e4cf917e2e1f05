// bench/calibrate: fits the built-in matcher's temperature, blur and floor (calibration.hpp) by
// the mean NLL of the true cell over development routes, and prints the fit, the NLL of the
// current defaults and of a uniform volume; then, on the volumes the defaults give, which ETU
// reference entropy fits the same criterion best (docs/filter.md); and one line of JSON.
//   bench_calibrate --cache A.gpkg ROUTE... [--cache B.gpkg ROUTE...]
// Routes are observation routes with ground truth (seqloc simulate). Use seeds that no report uses.

#include <algorithm>
#include <cmath>
#include <cstddef>
#include <cstdio>
#include <string>
#include <vector>

#include "seqloc/filter/config.hpp"
#include "seqloc/filter/seqloc_filter.hpp"
#include "seqloc/filter/types.hpp"
#include "seqloc/matcher/calibration.hpp"
#include "seqloc/pipeline/backbone_calibration.hpp"
#include "seqloc/pipeline/localize.hpp"

namespace pl = seqloc::pipeline;

namespace {

// ETU's reference entropies to compare (0: the paper's w = 1 - H; 1: ETU off, w = 1), and the
// fixed weights whose best per entropy band shows the shape a fitted w(H) would take.
const std::vector<double> kReferences{0, 0.8, 0.85, 0.88, 0.9, 0.92, 0.95, 0.98, 1};
const std::vector<double> kWeights{0.1, 0.25, 0.5, 0.75, 1, 1.25, 1.5, 2};

// One frame after the default calibration: its normalized entropy and, per weight, the log of the
// tempered frame normalize(p^w) at the true cell.
struct TemperedFrame {
  double entropy = 0;
  std::vector<double> at_reference;  // per kReferences
  std::vector<double> at_weight;     // per kWeights
};

// The log of normalize(p^w) at the true cell, as the filter tempers a frame (filter::temper_frame).
double log_tempered_at(const seqloc::filter::PreparedFrame& frame, std::size_t truth, double w) {
  return seqloc::filter::temper_frame(frame, w).log_prob[truth];
}

// truth: the true cell's index in the filter's [bin][v][u] layout.
TemperedFrame temper(std::vector<float> scores, double temperature,
                     const seqloc::matcher::VolumeCalibration& calibration, int size, int bins, std::size_t truth) {
  namespace sf = seqloc::filter;
  for (float& s : scores) s = static_cast<float>(s / temperature);
  seqloc::matcher::calibrate_volume(scores, size, size, bins, calibration, 2);
  // The frame as the filter's intake prepares it: its entropy is what ETU reads.
  const sf::PreparedFrame frame = sf::prepare_frame(
      sf::FrameVolume{scores.data(), sf::VolumeType::float32, sf::VolumeValues::log_prob, size, size, bins, 0.5}, bins, 2);
  TemperedFrame f;
  f.entropy = frame.entropy;
  for (const double r : kReferences) {
    const double w = r >= 1 ? 1.0 : sf::etu_weight(f.entropy, r);
    f.at_reference.push_back(log_tempered_at(frame, truth, w));
  }
  for (const double w : kWeights) f.at_weight.push_back(log_tempered_at(frame, truth, w));
  return f;
}

struct EtuFit {
  double best_reference = 0;  // 1: ETU off
  std::vector<double> nll;    // per kReferences
};

std::string reference_label(double r) {
  if (r >= 1) return "off";
  if (r == 0) return "paper";
  char label[16];
  std::snprintf(label, sizeof label, "%.2f", r);
  return label;
}

// Which ETU fits the calibrated frames best, by the same criterion as the calibration: the mean
// NLL of the true cell in the tempered frame; also on alternate frames in entropy order (how
// stable the choice is), and per fifth of the frames by entropy at fixed weights.
EtuFit report_etu(std::vector<TemperedFrame> frames) {
  EtuFit fit;
  if (frames.empty()) return fit;
  std::sort(frames.begin(), frames.end(), [](const auto& a, const auto& b) { return a.entropy < b.entropy; });
  const auto mean_nll = [&](std::size_t k, int half) {
    double sum = 0;
    std::size_t n = 0;
    for (std::size_t i = 0; i < frames.size(); ++i) {
      if (half >= 0 && static_cast<int>(i % 2) != half) continue;
      sum -= frames[i].at_reference[k];
      ++n;
    }
    return sum / static_cast<double>(n);
  };
  std::printf("\nETU on the calibrated frames, mean NLL of the true cell in normalize(p^w(H)):\n  %-18s", "H_ref");
  for (const double r : kReferences) std::printf(" %13s", reference_label(r).c_str());
  std::printf("\n  %-18s", "all frames");
  for (std::size_t k = 0; k < kReferences.size(); ++k) {
    fit.nll.push_back(mean_nll(k, -1));
    std::printf(" %13.3f", fit.nll.back());
  }
  fit.best_reference = kReferences[static_cast<std::size_t>(std::min_element(fit.nll.begin(), fit.nll.end()) - fit.nll.begin())];
  std::printf("\n  %-18s", "alternate frames");
  for (std::size_t k = 0; k < kReferences.size(); ++k) std::printf(" %6.3f/%6.3f", mean_nll(k, 0), mean_nll(k, 1));
  std::printf("\n  per fifth by entropy, at fixed w:\n  %-18s", "entropy");
  for (const double w : kWeights) std::printf(" w=%-6.3g", w);
  std::printf("\n");
  const std::size_t n = frames.size();
  for (std::size_t q = 0; q < 5; ++q) {
    const std::size_t lo = n * q / 5, hi = n * (q + 1) / 5;
    if (lo == hi) continue;
    std::printf("  %.3f-%.3f       ", frames[lo].entropy, frames[hi - 1].entropy);
    for (std::size_t k = 0; k < kWeights.size(); ++k) {
      double sum = 0;
      for (std::size_t i = lo; i < hi; ++i) sum -= frames[i].at_weight[k];
      std::printf(" %8.3f", sum / static_cast<double>(hi - lo));
    }
    std::printf("\n");
  }
  return fit;
}

}  // namespace

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
  const seqloc::matcher::MatcherConfig defaults;
  seqloc::matcher::MatcherConfig raw = defaults;
  raw.temperature = 1;  // the fit scales the raw scores itself
  raw.calibration = {};
  raw.threads = 2;
  const seqloc::matcher::BevMatcher matcher(raw);
  seqloc::matcher::CalibrationFit fit;
  auto grid = fit.grid();
  // The current defaults must be on the grid to be compared.
  if (std::find(grid.temperatures.begin(), grid.temperatures.end(), defaults.temperature) == grid.temperatures.end()) {
    grid.temperatures.push_back(defaults.temperature);
    fit = seqloc::matcher::CalibrationFit(grid);
  }
  const int size = raw.size, bins = raw.headings;
  std::size_t frames = 0;
  std::vector<TemperedFrame> tempered;
  for (const auto& [cache_path, routes] : sets) {
    seqloc::raster::CacheReader cache(cache_path);
    const auto projection = cache.metadata().projection();
    for (const auto& dir : routes) {
      const auto route = seqloc::io::read_route(dir);
      for (const auto& f : route.frames) {
        if (!f.truth || !f.truth->heading_deg || f.observation.empty()) continue;
        const auto scores = pl::match_frame(f, cache, matcher);
        const pl::GridCrop crop = pl::frame_crop(f, cache.grid(), projection);
        const auto cell = pl::true_volume_cell(f, crop, projection, size, size, bins, 0.5);
        const auto [v, u, b] = *cell;  // the frame has ground truth with a heading
        fit.add(scores, size, size, bins, v, u, b);
        if (u >= 0 && u < size && v >= 0 && v < size) {
          const auto true_cell = (static_cast<std::size_t>(b) * size + static_cast<std::size_t>(v)) * size +
                                 static_cast<std::size_t>(u);
          tempered.push_back(temper(scores, defaults.temperature, defaults.calibration, size, bins, true_cell));
        }
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
  const EtuFit etu = report_etu(tempered);
  const auto etu_nll = [&](double reference) {
    const auto at = std::find(kReferences.begin(), kReferences.end(), reference);
    return at == kReferences.end() || etu.nll.empty() ? std::nan("") : etu.nll[static_cast<std::size_t>(at - kReferences.begin())];
  };
  const double default_reference = seqloc::filter::FilterConfig{}.etu_reference_entropy;
  std::printf(
      "{\"frames\": %zu, \"skipped\": %zu, \"uniform_nll\": %.4f, \"current_nll\": %.4f, \"temperature\": %.4g, "
      "\"blur_cells\": %.4g, \"blur_bins\": %.4g, \"floor\": %.4g, \"nll\": %.4f, \"etu_best_reference\": %.4g, "
      "\"etu_nll_best\": %.4f, \"etu_nll_default\": %.4f, \"etu_nll_paper\": %.4f, \"etu_nll_off\": %.4f}\n",
      best.frames, best.skipped, best.uniform_nll, current, best.temperature, best.calibration.blur_cells,
      best.calibration.blur_bins, best.calibration.floor, best.nll, etu.best_reference, etu_nll(etu.best_reference),
      etu_nll(default_reference), etu_nll(0), etu_nll(1));
  return 0;
}
