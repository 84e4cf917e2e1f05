#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include "command.hpp"
#include "seqloc/core/error.hpp"
#include "seqloc/core/files.hpp"
#include "seqloc/io/route.hpp"
#include "seqloc/pipeline/match_routes.hpp"

namespace seqloc::app {
namespace {

namespace fs = std::filesystem;

class MatchCommand : public Command, public WithOverwrite, public WithProgress {
 public:
  void setup(CLI::App& app) override {
    app.add_option("cache", cache_path_, "Region cache (from seqloc preprocess)")->required();
    app.add_option("routes", route_dirs_, "Observation route folders (seqloc simulate's, docs/observation-format.md)")
        ->required();
    app.add_option("-o,--output", out_, "Output folder of volume routes (written whole, or not at all)")->required();
    add_matcher_options(app, options_.matcher);
    add_route_limit_options(app, limits_);
    app.add_option("--threads", options_.matcher.threads, "Matcher threads")
        ->default_val(default_threads())
        ->default_str("cores");
    add_overwrite_option(app, "output folder");
    add_progress_option(app);
    app.footer(
        "Writes OUT/<route>/{route.json,frames.csv,volumes/NNNNNN.npy}: each frame's volume from the built-in\n"
        "matcher as seqloc localize scores it (calibrated, normalized log-probabilities, float16, (H, W, N)),\n"
        "its crop in region-grid metres, the odometry, GPS and ground truth of the input route\n"
        "(docs/route-format.md). seqloc localize on them gives the poses it gives on the input routes.");
  }

  void check() override {
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
    const fs::path staged = core::staging_directory(out_);
    ProgressBar bar(show_progress(), "frames");
    std::size_t done = 0;
    for (const auto& route : routes) {
      pipeline::write_volume_route(route, cache, options_, staged / route.name,
                                   [&] { bar.update(static_cast<long long>(++done), static_cast<long long>(frames)); });
    }
    bar.done();
    core::commit_directory(staged, out_);
    std::printf("wrote %s (%zu routes, %zu frames)\n", out_.c_str(), routes.size(), frames);
    return kExitOk;
  }

 private:
  fs::path cache_path_, out_;
  std::vector<fs::path> route_dirs_;
  pipeline::LocalizeOptions options_;
  io::RouteLimits limits_;
};

}  // namespace

std::unique_ptr<Command> make_match_command() { return std::make_unique<MatchCommand>(); }

}  // namespace seqloc::app
