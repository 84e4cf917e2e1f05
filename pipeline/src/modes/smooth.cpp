// smooth: each frame's pose given every frame of the route (docs/localize.md, "smooth"), by the
// two-filter smoother (filter/smoother.hpp) in time linear in the route's length and memory
// independent of it.
//
// The seqloc filter runs forward over the route, its window following the vehicle, and writes its
// belief every kCheckpointFrames frames to an unlinked temporary file (with each frame's
// StepRecord in memory: a few hundred bytes). Then, from the route's end back to its start, one
// stretch of kCheckpointFrames frames at a time: the stretch's frames are read again, their
// forward beliefs recomputed from the stretch's checkpoint (ForwardReplay, bit for bit the first
// run's), and the backward filter carries beta over them, each frame's pose taken from
// alpha * beta. Cost: the forward pass, a replay and a backward pass (neither estimates anything),
// and every frame read twice. Memory: kCheckpointFrames forward beliefs, three filters and the
// stretch's frames. Disk: one window of float32 per kCheckpointFrames frames.
//
// A route that crosses regions is followed across: the forward belief handed over where the route
// enters the next region (SequentialLocalizer::hand_over), a stretch starting there (each stretch
// replayed in one region), and beta carried back into the previous region (BackwardPass::step_back).
#include <sys/types.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <filesystem>
#include <memory>
#include <optional>
#include <system_error>

#include "factories.hpp"
#include "seqloc/core/error.hpp"
#include "seqloc/core/files.hpp"
#include "seqloc/pipeline/backward_pass.hpp"
#include "seqloc/pipeline/sequential_localizer.hpp"

namespace seqloc::pipeline::modes {
namespace {

/// Frames per stretch: the forward beliefs held at once (and one checkpoint written per stretch).
constexpr std::size_t kCheckpointFrames = 8;

// Beliefs of one shape, by slot, in an unnamed temporary file.
class CheckpointFile {
 public:
  CheckpointFile(const std::filesystem::path& dir, std::size_t values)
      : dir_(dir.empty() ? std::filesystem::temp_directory_path() : dir), bytes_(values * sizeof(float)) {
    fd_ = core::open_unlinked_file(dir_, "seqloc-smooth");
    if (fd_ < 0) fail("cannot create a temporary file");
  }
  ~CheckpointFile() { ::close(fd_); }
  CheckpointFile(const CheckpointFile&) = delete;
  CheckpointFile& operator=(const CheckpointFile&) = delete;

  void write(std::size_t slot, const filter::BeliefVolume& belief) {
    const auto* p = reinterpret_cast<const char*>(belief.data());
    for (std::size_t done = 0; done < bytes_;) {
      const ssize_t n = ::pwrite(fd_, p + done, bytes_ - done, offset(slot, done));
      if (n <= 0) fail("cannot write a checkpoint to the temporary file");
      done += static_cast<std::size_t>(n);
    }
  }
  void read(std::size_t slot, filter::BeliefVolume& belief) const {
    auto* p = reinterpret_cast<char*>(belief.data());
    for (std::size_t done = 0; done < bytes_;) {
      const ssize_t n = ::pread(fd_, p + done, bytes_ - done, offset(slot, done));
      if (n <= 0) fail("cannot read a checkpoint back from the temporary file");
      done += static_cast<std::size_t>(n);
    }
  }

 private:
  [[nodiscard]] off_t offset(std::size_t slot, std::size_t done) const {
    return static_cast<off_t>(slot * bytes_ + done);
  }
  [[noreturn]] void fail(const std::string& what) const {
    const int error = errno != 0 ? errno : EIO;
    throw IoError("smooth: " + what + " in " + dir_.string() +
                  " (the forward pass's checkpoints): " + std::generic_category().message(error));
  }

  std::filesystem::path dir_;
  std::size_t bytes_;
  int fd_ = -1;
};

class SmoothMode final : public LocalizationMode {
 public:
  explicit SmoothMode(const RouteContext& context) : LocalizationMode(context) {}

  // The whole route is smoothed when its first pose is asked for.
  FrameEstimate estimate(std::size_t i, const GridCrop&, FramePrefetcher& frames) override {
    if (estimates_.empty()) run(frames);
    return estimates_.at(i);
  }

  void finish(io::RouteResult& result) override {
    LocalizationMode::finish(result);
    result.recentres += recentres_;
  }

 private:
  [[nodiscard]] std::vector<std::size_t> stretch_starts() const;
  void run(FramePrefetcher& frames);
  /// The forward pass, as the seqloc mode runs (the belief handed over where the route enters a
  /// region): each frame's record, and the forward belief at each stretch's start.
  void forward(FramePrefetcher& frames, const std::vector<std::size_t>& starts, std::vector<StepRecord>& records,
               CheckpointFile& checkpoints);

  std::vector<FrameEstimate> estimates_;
  int recentres_ = 0;
};

// The frames where a stretch starts: every kCheckpointFrames-th, and the first of each region a
// crossing route enters (so that a stretch's replay stays in one region).
std::vector<std::size_t> SmoothMode::stretch_starts() const {
  std::vector<std::size_t> starts;
  for (std::size_t t = 0; t < context_.route.frames.size(); ++t) {
    if (t == 0 || region_of(t) != region_of(t - 1) || t - starts.back() == kCheckpointFrames) starts.push_back(t);
  }
  return starts;
}

void SmoothMode::forward(FramePrefetcher& frames, const std::vector<std::size_t>& starts,
                         std::vector<StepRecord>& records, CheckpointFile& checkpoints) {
  const io::Route& route = context_.route;
  const std::size_t n = route.frames.size();
  const LocalizeOptions& options = context_.options;
  SequentialLocalizer localizer(cache_of(0), options.filter, /*online=*/false, options.recentre_margin, /*lag=*/0,
                                options.device);
  localizer.without_uncertainty();  // each frame's comes from its smoothed posterior
  // The early replay (FilterConfig::self_calibration_replay_frames) rewrites the route's first
  // records, and the checkpoints of stretches that start among them.
  auto stretch_of = [&starts](std::size_t t) { return std::find(starts.begin(), starts.end(), t) - starts.begin(); };
  localizer.want_replayed_alphas(
      [&](std::size_t t) { return stretch_of(t) < static_cast<std::ptrdiff_t>(starts.size()); });
  std::size_t stretch = 0;
  for (std::size_t t = 0; t < n; ++t) {
    const io::RouteFrame& f = route.frames[t];
    if (t > 0 && region_of(t) != region_of(t - 1)) localizer.hand_over(cache_of(t));
    const std::optional<GridFix> gps = frame_gps_fix(f, projection_of(t));
    const auto frame = frames.get_shared(t);  // kept, not copied, while the early replay keeps it
    const auto t0 = Clock::now();
    (void)localizer.step(frame, crop_in_region_of(t, t), f.odometry, gps);
    records[t] = localizer.last_step();
    for (auto& rewrite : localizer.take_rewritten()) {
      records[rewrite.index] = rewrite.record;
      if (rewrite.alpha) checkpoints.write(static_cast<std::size_t>(stretch_of(rewrite.index)), *rewrite.alpha);
    }
    if (stretch < starts.size() && starts[stretch] == t) checkpoints.write(stretch++, localizer.filter()->belief());
    filter_seconds_ += seconds_since(t0);
    frames.release(t);
  }
  recentres_ = localizer.recentres();
}

void SmoothMode::run(FramePrefetcher& frames) {
  const io::Route& route = context_.route;
  const std::size_t n = route.frames.size();
  const LocalizeOptions& options = context_.options;
  std::vector<StepRecord> records(n);
  const std::vector<std::size_t> starts = stretch_starts();
  CheckpointFile checkpoints(options.spill_dir, static_cast<std::size_t>(options.filter.width) *
                                                    static_cast<std::size_t>(options.filter.height) *
                                                    static_cast<std::size_t>(options.filter.headings));

  forward(frames, starts, records, checkpoints);

  // Backward, a stretch at a time from the route's end; each stretch's frames read again in order,
  // the next one prepared meanwhile. A stretch is replayed in its region; beta is carried into
  // the previous region where the route entered the next.
  frames.set_lookahead(false);
  frames.prefetch(starts.back());
  BackwardPass backward(cache_of(n - 1), options.filter);
  std::vector<std::unique_ptr<ForwardReplay>> replays;  // by region, made when first needed
  std::vector<filter::BeliefVolume> alpha;
  std::vector<std::shared_ptr<const filter::PreparedFrame>> kept;
  estimates_.resize(n);
  backward.start(records[n - 1]);
  for (std::size_t s = starts.size(); s-- > 0;) {
    const std::size_t first = starts[s], last = (s + 1 < starts.size() ? starts[s + 1] : n) - 1;
    const std::size_t count = last - first + 1;
    if (alpha.size() < count) {
      alpha.resize(count, filter::BeliefVolume(options.filter.width, options.filter.height, options.filter.headings));
    }
    const std::size_t region = region_of(first);
    if (replays.size() <= region) replays.resize(region + 1);
    if (!replays[region]) replays[region] = std::make_unique<ForwardReplay>(cache_of(first), options.filter);
    ForwardReplay& replay = *replays[region];
    kept.assign(count, nullptr);
    for (std::size_t t = first; t <= last; ++t) {
      kept[t - first] = frames.get_shared(t);
      frames.prefetch(t < last ? t + 1 : (s > 0 ? starts[s - 1] : n));
      frames.release(t);
      const auto t0 = Clock::now();
      if (t == first) {
        checkpoints.read(s, alpha[0]);
        replay.resume(alpha[0], records[first]);
      } else {
        replay.step(records[t], *kept[t - first], alpha[t - 1 - first]);  // alpha of t - 1 handed over
      }
      if (t == last && t > first) replay.hand_belief_to(alpha[t - first]);
      filter_seconds_ += seconds_since(t0);
    }
    const auto t0 = Clock::now();
    for (std::size_t t = last + 1; t-- > first;) {
      estimates_[t] = backward.estimate(alpha[t - first], records[t]);
      if (t > 0) backward.step_back(records[t], *kept[t - first], records[t - 1], cache_of(t - 1));
    }
    filter_seconds_ += seconds_since(t0);
  }
}

}  // namespace

std::unique_ptr<LocalizationMode> make_smooth(const RouteContext& context) {
  return std::make_unique<SmoothMode>(context);
}

}  // namespace seqloc::pipeline::modes
