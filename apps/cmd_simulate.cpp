#include <cstdio>
#include <filesystem>

#include "command.hpp"
#include "seqloc/core/error.hpp"
#include "seqloc/sim/simulate.hpp"

namespace seqloc::app {
namespace {

namespace fs = std::filesystem;

class SimulateCommand : public Command, public WithOverwrite, public WithProgress {
 public:
  void setup(CLI::App& app) override {
    app.add_option("cache", cache_path_, "Region cache (from seqloc preprocess)")->required();
    app.add_option("-o,--output", out_, "Output folder of route folders (written whole, or not at all)")->required();
    auto& o = options_;
    app.add_option("--routes", o.routes, "Number of routes")->default_val(o.routes);
    app.add_option("--frames", o.frames, "Frames per route")->default_val(o.frames);
    app.add_option("--seed", o.seed, "Seed of every random draw")->default_val(o.seed);
    app.add_option("--min-spacing", o.min_spacing_m, "Shortest distance between frames, m")->default_val(o.min_spacing_m);
    app.add_option("--max-spacing", o.max_spacing_m, "Longest distance between frames, m")->default_val(o.max_spacing_m);
    app.add_option("--gps-error", o.gps_error_m, "Radius of the crop centre's (GPS) error, m")->default_val(o.gps_error_m);
    auto& c = o.camera;
    app.add_option("--range", c.range_m, "Camera: visibility radius, m")->default_val(c.range_m);
    app.add_option("--fov", c.fov_deg, "Camera: field of view, degrees (360 = panorama)")->default_val(c.fov_deg);
    app.add_flag("!--no-occlusion", c.occlusion, "Camera: see through buildings");
    app.add_option("--class-miss", c.class_miss, "Noise: probability a seen class is missed in a frame")
        ->default_val(c.class_miss);
    app.add_option("--cell-dropout", c.cell_dropout, "Noise: probability a seen cell is missed")->default_val(c.cell_dropout);
    app.add_option("--spurious", c.spurious_blobs, "Noise: mean number of spurious blobs per frame")
        ->default_val(c.spurious_blobs);
    app.add_option("--jitter", c.jitter_m, "Noise: sigma of the observation's position error, m")->default_val(c.jitter_m);
    app.add_option("--jitter-deg", c.jitter_deg, "Noise: sigma of its heading error, degrees")->default_val(c.jitter_deg);
    app.add_option("--wrong-frames", c.wrong_frame, "Noise: probability a frame shows another place")
        ->default_val(c.wrong_frame);
    app.add_flag("--clean", clean_, "No perception noise at all (every noise option 0)");
    add_overwrite_option(app, "output folder");
    add_progress_option(app);
    app.footer("Writes OUT/route_NNN/{route.json,frames.csv,observations/*.png}: routes along the cache's roads with\n"
               "ground truth, BEV observations for the built-in matcher and a GPS-like crop (docs/simulate.md).");
  }

  void check() override {
    if (clean_) {
      auto& c = options_.camera;
      c.class_miss = c.cell_dropout = c.spurious_blobs = c.jitter_m = c.jitter_deg = c.wrong_frame = 0;
    }
    validate_options([&] { options_.validate(); });
    check_overwrite(out_);
  }

  int run() override {
    raster::CacheReader cache(cache_path_, 256);
    ProgressBar bar(show_progress(), "routes");
    sim::simulate_routes(cache, options_, out_, [&](int done, int total) { bar.update(done, total); });
    bar.done();
    std::printf("wrote %s (%d routes of %d frames)\n", out_.c_str(), options_.routes, options_.frames);
    return kExitOk;
  }

 private:
  fs::path cache_path_, out_;
  sim::SimulateOptions options_;
  bool clean_ = false;
};

}  // namespace

std::unique_ptr<Command> make_simulate_command() { return std::make_unique<SimulateCommand>(); }

}  // namespace seqloc::app
