#include <cstdio>
#include <filesystem>
#include <optional>
#include <span>

#include "command.hpp"
#include "seqloc/core/error.hpp"
#include "seqloc/core/files.hpp"
#include "seqloc/io/run_folder.hpp"
#include "seqloc/pipeline/localize.hpp"
#include "seqloc/render/render.hpp"

namespace seqloc::app {
namespace {

namespace fs = std::filesystem;

class RenderCommand : public Command {
 public:
  void setup(CLI::App& app) override {
    app.add_option("cache", cache_path_, "Region cache (from seqloc preprocess)")->required();
    app.add_option("route", route_dir_, "Route folder (route.json + frames.csv)")->required();
    app.add_option("-o,--output", out_, "Folder for the PNG figures (created)")->required();
    app.add_option("--localized", localized_,
                   "An output folder of seqloc localize for this route: its modes' poses are drawn, and the SeqLoc "
                   "beliefs and frame likelihoods it kept with --beliefs; without it (or without its beliefs), "
                   "single and seqloc are run here first");
    app.add_option("--frame", frame_,
                   "Frame of the likelihood figure (index from 0); 'collapse': the frame on which the SeqLoc belief "
                   "shrinks most while its error falls to 5 m or less; 'sharpest': the frame after the first whose "
                   "own likelihood has the lowest entropy")
        ->default_val("0");
    app.add_option("--window", window_, "Belief window, cells")->capture_default_str();
    app.add_option("--threads", localize_.filter.threads, "Threads")->default_val(2);
    app.footer(
        "Writes overview.png (the route's estimates over the map, coloured by position error, and the ground\n"
        "truth), likelihood_K.png (the frame's own likelihood and the SeqLoc belief over the map, the ground\n"
        "truth as a star), entropy_route.png and error_over_time.png; every map with a scale bar, north arrow\n"
        "and legend (docs/render.md).");
  }

  void check() override {
    localize_.filter.width = localize_.filter.height = window_;
    localize_.matcher.threads = localize_.filter.threads;
    localize_.keep_beliefs = true;
    validate_options([&] { localize_.validate(); });
    if (frame_ != "collapse" && frame_ != "sharpest") options_.frame = parse_frame(frame_);
  }

  int run() override {
    raster::CacheReader cache(cache_path_, 256);
    const io::Route route = io::read_route(route_dir_);
    std::vector<std::pair<std::string, std::vector<io::FramePose>>> poses;
    const io::RunFolder run(localized_);
    if (!localized_.empty()) {
      if (!run.has_route(route.name)) {
        throw seqloc::UsageError((localized_ / route.name).string() + ": no localize results for route '" + route.name +
                                 "' there");
      }
      // Every mode the run has (smooth's too), in the recall table's order.
      for (auto& [mode, mode_poses] : run.route_poses(route.name))
        poses.emplace_back(io::mode_name(mode), std::move(mode_poses));
    }
    // The figure draws what localize --beliefs kept: the given run's, else a run made here.
    std::optional<ScratchRun> scratch;
    if (!localized_.empty() && run.has_beliefs(route.name, io::Mode::seqloc)) {
      options_.beliefs_dir = run.mode_dir(route.name, io::Mode::seqloc);
    } else {
      scratch.emplace();
      options_.beliefs_dir = scratch->localize(route, cache, localize_, poses);
    }
    if (frame_ == "collapse") {
      std::span<const io::FramePose> seqloc;
      for (const auto& [mode, p] : poses) {
        if (mode == "seqloc") seqloc = p;
      }
      options_.frame = render::collapse_frame(options_.beliefs_dir, route.frames.size(), seqloc);
    } else if (frame_ == "sharpest") {
      options_.frame = sharpest_frame(poses);
    }
    for (const auto& file : render::render_route(cache, route, poses, options_, out_))
      std::printf("wrote %s\n", file.c_str());
    return kExitOk;
  }

 private:
  static std::size_t parse_frame(const std::string& text) {
    const auto v = parse_numbers<std::size_t>(text, ',', 1);
    if (!v) throw seqloc::UsageError("--frame '" + text + "': expected a frame index, 'collapse' or 'sharpest'");
    return (*v)[0];
  }

  // The frame (after the first) whose own likelihood is sharpest, from any mode's poses.
  static std::size_t sharpest_frame(const std::vector<std::pair<std::string, std::vector<io::FramePose>>>& poses) {
    if (poses.empty() || poses.front().second.size() < 2) return 0;
    const auto& p = poses.front().second;
    std::size_t best = 1;
    for (std::size_t i = 2; i < p.size(); ++i) {
      if (p[i].entropy < p[best].entropy) best = i;
    }
    return best;
  }

  // A run of seqloc localize --beliefs made for the figure in a temporary folder, removed after.
  class ScratchRun {
   public:
    // This process's folder, after removing those that killed runs left behind.
    ScratchRun() : root_(core::staging_directory(fs::temp_directory_path() / "seqloc-render")) {}
    ScratchRun(const ScratchRun&) = delete;
    ScratchRun& operator=(const ScratchRun&) = delete;
    ~ScratchRun() {
      std::error_code ec;
      fs::remove_all(root_, ec);
    }
    // Runs seqloc (and single, when `poses` is empty, adding both to it) and returns the folder of
    // seqloc's beliefs.
    fs::path localize(const io::Route& route, raster::CacheReader& cache, const pipeline::LocalizeOptions& options,
                      std::vector<std::pair<std::string, std::vector<io::FramePose>>>& poses) {
      const bool both = poses.empty();
      const std::vector<io::Mode> modes =
          both ? std::vector{io::Mode::single, io::Mode::seqloc} : std::vector{io::Mode::seqloc};
      auto batch = pipeline::localize_routes({route}, cache, options, modes);
      fs::create_directories(dir(route.name));
      for (auto& result : batch.results) {
        if (result.mode == io::Mode::seqloc) io::write_route_outputs(dir(route.name), result);
        if (both) poses.emplace_back(io::mode_name(result.mode), std::move(result.poses));
      }
      return dir(route.name);
    }

   private:
    [[nodiscard]] fs::path dir(const std::string& route) const { return root_ / route / "seqloc"; }
    fs::path root_;
  };

  fs::path cache_path_, route_dir_, out_, localized_;
  std::string frame_;
  render::RenderOptions options_;
  pipeline::LocalizeOptions localize_;
  int window_ = filter::FilterConfig{}.width;
};

}  // namespace

std::unique_ptr<Command> make_render_command() { return std::make_unique<RenderCommand>(); }

}  // namespace seqloc::app
