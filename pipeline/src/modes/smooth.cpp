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
#include <sys/types.h>
#include <unistd.h>

#include <cerrno>
#include <filesystem>
#include <memory>
#include <optional>
#include <system_error>

#include "../unlinked_file.hpp"
#include "factories.hpp"
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
    fd_ = detail::open_unlinked_file(dir_, "seqloc-smooth");
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
    throw std::system_error(error, std::generic_category(),
                            "smooth: " + what + " in " + dir_.string() + " (the forward pass's checkpoints)");
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

  void finish(RouteResult& result) override {
    LocalizationMode::finish(result);
    result.recentres += recentres_;
  }

 private:
  void run(FramePrefetcher& frames);

  std::vector<FrameEstimate> estimates_;
  int recentres_ = 0;
};

void SmoothMode::run(FramePrefetcher& frames) {
  const Route& route = context_.route;
  const std::size_t n = route.frames.size();
  const LocalizeOptions& options = context_.options;
  const auto& projection = context_.cache.metadata().projection();
  std::vector<StepRecord> records(n);
  const std::size_t stretches = (n + kCheckpointFrames - 1) / kCheckpointFrames;
  CheckpointFile checkpoints(options.spill_dir, static_cast<std::size_t>(options.filter.width) *
                                                    static_cast<std::size_t>(options.filter.height) *
                                                    static_cast<std::size_t>(options.filter.headings));

  // Forward, as the seqloc mode runs.
  {
    SequentialLocalizer forward(context_.cache, options.filter, /*online=*/false, options.recentre_margin);
    for (std::size_t t = 0; t < n; ++t) {
      const RouteFrame& f = route.frames[t];
      const GridCrop crop = frame_crop(f, context_.cache.grid(), projection);
      std::optional<GridFix> gps;
      if (f.gps) {
        const auto g = projection.forward(f.gps->where);
        gps = GridFix{g.x_m, g.y_m, f.gps->sigma_m};
      }
      const auto& frame = frames.get(t);
      const auto t0 = Clock::now();
      (void)forward.step(frame, crop, f.odometry, gps);
      records[t] = forward.last_step();
      if (t % kCheckpointFrames == 0) checkpoints.write(t / kCheckpointFrames, forward.filter()->belief());
      filter_seconds_ += seconds_since(t0);
      frames.release(t);
    }
    recentres_ = forward.recentres();
  }

  // Backward, a stretch at a time from the route's end; each stretch's frames read again in order,
  // the next one prepared meanwhile.
  frames.set_lookahead(false);
  frames.prefetch((stretches - 1) * kCheckpointFrames);
  BackwardPass backward(context_.cache, options.filter);
  ForwardReplay replay(context_.cache, options.filter);
  std::vector<filter::BeliefVolume> alpha;
  std::vector<std::shared_ptr<const filter::PreparedFrame>> kept;
  estimates_.resize(n);
  backward.start(records[n - 1]);
  for (std::size_t s = stretches; s-- > 0;) {
    const std::size_t first = s * kCheckpointFrames, last = std::min(n, first + kCheckpointFrames) - 1;
    const std::size_t count = last - first + 1;
    if (alpha.size() < count) {
      alpha.resize(count, filter::BeliefVolume(options.filter.width, options.filter.height, options.filter.headings));
    }
    kept.assign(count, nullptr);
    for (std::size_t t = first; t <= last; ++t) {
      kept[t - first] = frames.get_shared(t);
      frames.prefetch(t < last ? t + 1 : (s > 0 ? first - kCheckpointFrames : n));
      frames.release(t);
      const auto t0 = Clock::now();
      if (t == first) {
        checkpoints.read(s, alpha[0]);
        replay.resume(alpha[0], records[first]);
      } else {
        replay.step(records[t], *kept[t - first]);
        alpha[t - first] = replay.belief();
      }
      filter_seconds_ += seconds_since(t0);
    }
    const auto t0 = Clock::now();
    for (std::size_t t = last + 1; t-- > first;) {
      estimates_[t] = backward.estimate(alpha[t - first], records[t]);
      if (t > 0) backward.step_back(records[t], *kept[t - first], records[t - 1]);
    }
    filter_seconds_ += seconds_since(t0);
  }
}

}  // namespace

std::unique_ptr<LocalizationMode> make_smooth(const RouteContext& context) {
  return std::make_unique<SmoothMode>(context);
}

}  // namespace seqloc::pipeline::modes
