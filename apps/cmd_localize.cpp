#include <array>
#include <cstdio>
#include <filesystem>
#include <string>
#include <utility>
#include <vector>

#include "command.hpp"
#include "seqloc/core/error.hpp"
#include "seqloc/io/run_folder.hpp"
#include "seqloc/pipeline/localize.hpp"
#include "seqloc/pipeline/localize_run.hpp"
#include "seqloc/ros/route_bag.hpp"

namespace seqloc::app {
namespace {

namespace fs = std::filesystem;

class LocalizeCommand : public Command, public WithOverwrite, public WithProgress {
 public:
  void setup(CLI::App& app) override {
    app.add_option("cache", cache_path_, "Region cache (from seqloc preprocess), or a folder of region caches")
        ->required();
    app.add_option("routes", route_dirs_, "Route folders (route.json + frames.csv, see docs/route-format.md)")
        ->required();
    app.add_option("-o,--output", out_, "Output folder (written whole, or not at all)")->required();
    app.add_option("--region", extra_regions_,
                   "Another region cache or folder of them (repeatable): a route crossing from one region into the "
                   "next is followed across, in every mode (docs/localize.md)");
    app.add_option("--mode", mode_,
                   "seqloc, online (naive recursion), single, offline (uses future frames), smooth (each frame given "
                   "the whole route: the best poses for batch work), or all")
        ->default_val("seqloc")
        ->check(CLI::IsMember({"seqloc", "online", "single", "offline", "smooth", "all"}));
    app.add_option("--lag", options_.lag,
                   "seqloc and online: report each frame's pose given the L frames after it too (fixed-lag smoothing: "
                   "real time with a delay of L frames; keeps L + 1 windows in memory)")
        ->capture_default_str()
        ->check(CLI::NonNegativeNumber);
    app.add_option("--offline-window", options_.offline_half_window,
                   "Offline mode: frames within K of each frame are aligned and summed (-1: all)")
        ->capture_default_str();
    // Every filter setting from the filter's field table; the window and threads have their own.
    add_filter_options(app, options_.filter, {"width", "height", "threads"});
    app.add_option("--window", window_, "Belief window, cells of 0.5 m each way")->capture_default_str();
    app.add_option("--threads", options_.filter.threads,
                   "Threads: routes run side by side, or one route's filter uses them all")
        ->default_val(default_threads())
        ->default_str("cores");
    app.add_option("--odometry-noise", noise_, "SIGMA_T_PCT,SIGMA_R_DEG_PER_M: perturb the odometry (KITTI style)");
    app.add_option("--seed", seed_, "Seed of the odometry noise")->default_val(1);
    add_route_limit_options(app, limits_);
    app.add_option("--max-crop-jump", options_.max_crop_jump_m,
                   "Largest distance between consecutive crop centres, m (0: the window's size)")
        ->capture_default_str();
    app.add_option("--max-crop-outside", options_.max_crop_outside_m,
                   "How far beyond the region's edge a crop centre may lie, m (0: crops must be in the region)")
        ->capture_default_str();
    app.add_option("--volume-temperature", options_.volume_temperature,
                   "Divide every volume's log-probabilities by T and renormalize (T > 1 flattens an overconfident "
                   "backbone, T < 1 sharpens)")
        ->capture_default_str();
    app.add_option("--calibration", calibration_,
                   "A calibration file from seqloc calibrate: its temperature, blur and floor applied to every volume "
                   "(instead of --volume-temperature)");
    add_matcher_options(app, options_.matcher);
    app.add_option("--shard", shard_text_,
                   "Localize only shard I of N (I/N, 0-based: every N-th route in sorted order from the I-th), e.g. "
                   "--shard $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT; merge the outputs with `seqloc evaluate`");
    app.add_option("--frame-memory", options_.frame_memory_mb,
                   "Memory for the frames a route's modes share, MB (float16; beyond it they go to a temporary file)")
        ->capture_default_str();
    app.add_option("--device", device_,
                   "The forward filter of online, seqloc and smooth on: cpu; cuda (the GPU, docs/gpu.md);\n"
                   "cuda-host (the CUDA kernels on the CPU: slow, checks them without a GPU)")
        ->check(CLI::IsMember({"cpu", "cuda", "cuda-host"}))
        ->capture_default_str();
    app.add_flag("--beliefs", options_.keep_beliefs,
                 "Online and seqloc: also write beliefs.npy (each frame's belief summed over headings), beliefs.csv "
                 "(their windows) and likelihoods.npy (each frame's own likelihood in its window), which seqloc "
                 "render draws");
    app.add_flag("--mcap", mcap_,
                 "Also write each route's poses as a ROS 2 bag (MCAP, CDR) for Foxglove and rosbag2, in\n"
                 "OUT/<route>/<mode>/bag/ for the modes with a belief: online, seqloc, smooth (docs/ros.md)");
    app.add_option("--mcap-frame-id", bag_.frame_id, "The bag's local east-north-up frame: the poses' frame_id")
        ->capture_default_str();
    app.add_option("--mcap-base-frame", bag_.base_frame, "The vehicle's frame: the NavSatFix messages' frame_id")
        ->capture_default_str();
    app.add_option("--mcap-origin", mcap_origin_,
                   "LAT,LON: the local frame's origin (default: the route's first true position, else its first pose)");
    add_overwrite_option(app, "output folder");
    add_progress_option(app);
    app.footer(
        "Routes with an 'observation' column are scored by the built-in matcher (docs/matcher.md).\n"
        "Writes OUT/<route>/<mode>/{poses.csv,track.geojson,trajectory.tum,metrics.json} (and groundtruth.tum\n"
        "when the route has ground truth) and OUT/summary.json (with --mcap, also OUT/<route>/<mode>/bag/),\n"
        "and prints the recall table. Any bad input stops the run with nothing written.");
  }

  void check() override {
    options_.filter.width = options_.filter.height = window_;
    validate_options([&] {
      options_.validate();
      limits_.validate();
    });
    options_.device = pipeline::device_from_name(device_).value();  // CLI::IsMember checked it
    // Before any work, with one line saying why (no GPU, no driver, a build without CUDA).
    pipeline::check_device(options_.device, options_.filter);
    check_overwrite(out_);
    std::error_code ec;
    const auto parent = out_.has_parent_path() ? out_.parent_path() : fs::path(".");
    if (!fs::is_directory(parent, ec)) {
      throw seqloc::UsageError(out_.string() + ": output directory '" + parent.string() + "' does not exist");
    }
    if (!noise_.empty()) {
      const auto v = parse_numbers<double>(noise_, ',', 2);
      if (v) noise_t_ = (*v)[0], noise_r_ = (*v)[1];
      if (!v || noise_t_ < 0 || noise_r_ < 0) {
        throw seqloc::UsageError("--odometry-noise '" + noise_ + "': expected SIGMA_T_PCT,SIGMA_R_DEG_PER_M >= 0");
      }
    }
    // --mode is one of the mode names or "all" (CLI::IsMember checked it).
    if (mode_ == "all") {
      modes_.assign(io::kModes.begin(), io::kModes.end());
    } else {
      modes_ = {io::parse_mode(mode_).value()};
    }
    if (!mcap_origin_.empty()) {
      const auto v = parse_numbers<double>(mcap_origin_, ',', 2);
      if (!v) throw seqloc::UsageError("--mcap-origin '" + mcap_origin_ + "': expected LAT,LON in degrees");
      bag_.origin_deg = std::array<double, 2>{(*v)[0], (*v)[1]};
    }
    if (!mcap_ && (!mcap_origin_.empty() || bag_.frame_id != ros::BagOptions{}.frame_id ||
                   bag_.base_frame != ros::BagOptions{}.base_frame)) {
      throw seqloc::UsageError("--mcap-frame-id, --mcap-base-frame and --mcap-origin go with --mcap");
    }
    if (!shard_text_.empty()) {
      const auto v = parse_numbers<int>(shard_text_, '/', 2);
      if (!v || (*v)[1] < 1 || (*v)[0] < 0 || (*v)[0] >= (*v)[1]) {
        throw seqloc::UsageError("--shard '" + shard_text_ + "': expected I/N with 0 <= I < N, e.g. 0/4");
      }
      shard_ = {(*v)[0], (*v)[1]};
    }
  }

  int run() override {
    pipeline::LocalizeRun job;
    job.regions = {cache_path_};
    job.regions.insert(job.regions.end(), extra_regions_.begin(), extra_regions_.end());
    job.routes = route_dirs_;
    job.output = out_;
    job.modes = modes_;
    job.options = options_;
    job.calibration = calibration_;
    job.limits = limits_;
    job.shard = shard_;
    job.noise = {noise_t_, noise_r_, seed_};
    if (mcap_) job.bags = bag_;
    ProgressBar bar(show_progress(), "frames");
    const auto report =
        pipeline::run_localize(std::move(job), {[&](const std::string& line) { log("%s", line.c_str()); },
                                                [&](long long done, long long total) { bar.update(done, total); }});
    bar.done();
    log("%zu volumes scored or read for %lld frames and %zu modes; %zu spilled to a temporary file; at most %.0f MB "
        "per route",
        report.frames_made, report.frames, modes_.size(), report.frames_spilled,
        static_cast<double>(report.peak_frame_memory_bytes) / (1 << 20));
    std::fputs(io::format_table(report.metrics).c_str(), stdout);
    if (mcap_) {
      std::printf("wrote %s (%zu routes, %zu ROS 2 bags)\n", out_.c_str(), report.routes, report.bags);
    } else {
      std::printf("wrote %s (%zu routes)\n", out_.c_str(), report.routes);
    }
    return kExitOk;
  }

 private:
  fs::path cache_path_;
  std::vector<fs::path> extra_regions_;
  std::vector<fs::path> route_dirs_;
  fs::path out_;
  fs::path calibration_;
  std::string mode_ = "seqloc";
  std::string device_ = "cpu";
  pipeline::LocalizeOptions options_;
  int window_ = filter::FilterConfig{}.width;
  std::string noise_;
  std::string shard_text_;
  std::uint64_t seed_ = 1;
  io::RouteLimits limits_;
  bool mcap_ = false;
  ros::BagOptions bag_;
  std::string mcap_origin_;
  // What check() made of the options.
  std::vector<io::Mode> modes_;
  io::Shard shard_;
  double noise_t_ = 0, noise_r_ = 0;
};

}  // namespace

std::unique_ptr<Command> make_localize_command() { return std::make_unique<LocalizeCommand>(); }

}  // namespace seqloc::app
