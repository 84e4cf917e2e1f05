#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "command.hpp"
#include "seqloc/core/error.hpp"
#include "seqloc/core/files.hpp"
#include "seqloc/io/route.hpp"
#include "seqloc/pipeline/backbone_calibration.hpp"

namespace seqloc::app {
namespace {

namespace fs = std::filesystem;

class CalibrateCommand : public Command, public WithOverwrite, public WithProgress {
 public:
  void setup(CLI::App& app) override {
    app.add_option("cache", cache_path_, "Region cache (from seqloc preprocess)")->required();
    app.add_option("routes", route_dirs_, "Route folders with ground truth (gt_lat, gt_lon, gt_heading_deg)")
        ->required();
    app.add_option("-o,--output", out_, "The calibration file to write (JSON)")->required();
    add_matcher_options(app, options_.matcher);
    add_route_limit_options(app, limits_);
    app.add_option("--threads", options_.matcher.threads, "Threads")
        ->default_val(default_threads())
        ->default_str("cores");
    add_overwrite_option(app, "calibration file");
    add_progress_option(app);
    app.footer(
        "Fits a temperature, a blur and a floor to the routes' volumes (.npy from any backbone, or the built-in\n"
        "matcher's) by the mean negative log-likelihood of the true cell, prints the fit against the volumes as\n"
        "given and a uniform volume, and writes them for `seqloc localize --calibration` and the Python module\n"
        "(docs/localize.md). Use routes that you do not report results on.");
  }

  void check() override {
    options_.filter.threads = options_.matcher.threads;
    validate_options([&] {
      options_.validate();
      limits_.validate();
    });
    check_overwrite(out_);
  }

  int run() override {
    raster::CacheReader cache(cache_path_, 256);
    const auto routes = read_checked_routes(route_dirs_, limits_, cache, options_);
    const std::size_t frames = io::frame_count(routes);
    ProgressBar bar(show_progress(), "frames");
    std::size_t done = 0;
    const auto fit = pipeline::fit_backbone_calibration(
        routes, cache, options_, [&] { bar.update(static_cast<long long>(++done), static_cast<long long>(frames)); });
    bar.done();
    const auto& b = fit.best;
    std::printf("frames %zu (true cell outside the volume: %zu)\n", b.frames, b.skipped);
    std::printf("fit: temperature %g, blur %g cells / %g bins, floor %g\n", b.temperature, b.calibration.blur_cells,
                b.calibration.blur_bins, b.calibration.floor);
    std::printf("mean NLL of the true cell (nats): fit %.3f, as given %.3f, uniform %.3f\n", b.nll, fit.as_given_nll,
                b.uniform_nll);
    core::write_file(out_, pipeline::calibration_json(fit));
    std::printf("wrote %s\n", out_.c_str());
    return kExitOk;
  }

 private:
  fs::path cache_path_, out_;
  std::vector<fs::path> route_dirs_;
  pipeline::LocalizeOptions options_;
  io::RouteLimits limits_;
};

}  // namespace

std::unique_ptr<Command> make_calibrate_command() { return std::make_unique<CalibrateCommand>(); }

}  // namespace seqloc::app
