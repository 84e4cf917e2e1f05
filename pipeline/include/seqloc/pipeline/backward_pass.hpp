#pragma once
// The smoother's passes over a region (docs/localize.md, "smooth and --lag"): what the forward
// filter did at each frame (StepRecord), the backward filter in a window that retraces the forward
// window's moves (BackwardPass), and the forward filter run again from a kept belief, step for
// step as it ran the first time (ForwardReplay: smooth's recomputation between checkpoints).

#include <array>
#include <cstdint>
#include <optional>
#include <utility>

#include "seqloc/filter/smoother.hpp"
#include "seqloc/pipeline/modes.hpp"
#include "seqloc/pipeline/region_window.hpp"

namespace seqloc::pipeline {

/// What the forward pass did at one frame: all a second pass needs to repeat it or to reverse it.
/// The forward belief after frame t (alpha_t) is taken as it stands after the whole step, in the
/// window of `origin_after`; the frame's crop and fix are in the window of `origin`.
struct StepRecord {
  std::array<std::int64_t, 2> origin{};        ///< region pixel of window cell (0, 0) when the frame was taken in
  std::array<std::int64_t, 2> origin_after{};  ///< the same after the step re-centred the window on its estimate
  filter::CropPose crop;                       ///< the frame's crop in that window
  filter::Odometry odometry;                   ///< from the previous frame
  std::optional<filter::GpsFix> fix;           ///< the GPS term's fix in that window, when the filter used one
  filter::FrameWeighting weighting;            ///< how the filter weighed the frame
  FrameEstimate filtered;                      ///< the forward filter's estimate (frames <= t)
};

/// beta over a window of the region: from the last frame of a stretch (no later frames) back to
/// earlier ones, each frame's likelihood weighed as the forward pass weighed it.
class BackwardPass {
 public:
  BackwardPass(raster::CacheReader& cache, const filter::FilterConfig& config);

  /// At frame `last`, with no frames after it: beta uniform, the window where the forward one was.
  void start(const StepRecord& last);
  /// start() at a frame of `region` (the pass is in the region it was made for, or last carried to).
  void start(const StepRecord& last, raster::CacheReader& region);
  /// The smoothed estimate of the frame beta stands at, from its forward belief `alpha` (after the
  /// frame's step, in the window of record.origin_after): position and heading of alpha * beta, and the forward
  /// filter's entropy, weights and flag.
  [[nodiscard]] FrameEstimate estimate(const filter::BeliefVolume& alpha, const StepRecord& record);
  /// Takes frame t in (`record`, `frame`), then moves back to frame t - 1, into the window of
  /// `previous` (its record).
  void step_back(const StepRecord& record, const filter::PreparedFrame& frame, const StepRecord& previous);
  /// step_back() to a frame of another region (`previous_region`, which the forward pass left at
  /// frame t): beta is carried into that region's window of `previous` (carry_belief). With the
  /// region beta is in, this is step_back().
  void step_back(const StepRecord& record, const filter::PreparedFrame& frame, const StepRecord& previous,
                 raster::CacheReader& previous_region);

 private:
  filter::FilterConfig config_;
  RegionWindow window_;
  filter::BackwardFilter filter_;
  std::optional<filter::BeliefVolume> posterior_;  ///< the last estimate's smoothed posterior
};

/// The forward filter resumed from a belief it had, repeating its recorded steps exactly: the same
/// window moves, the same weighting, so that the beliefs equal the first run's bit for bit.
class ForwardReplay {
 public:
  ForwardReplay(raster::CacheReader& cache, const filter::FilterConfig& config);

  /// Resumes after frame t with `alpha`, the forward filter's belief then (`record`: frame t's).
  void resume(const filter::BeliefVolume& alpha, const StepRecord& record);
  /// The next frame, `record` and `frame`; belief() is then its alpha. Returns the update's result
  /// (its pose from the replayed belief). `predict` false: the route's first frame, taken in
  /// without a prediction as the filter takes it.
  filter::FrameResult step(const StepRecord& record, const filter::PreparedFrame& frame, bool predict = true);
  /// step(), and the belief before it (the last step's alpha) handed to `previous`: by exchanging
  /// storage where the window did not move in between, else copied.
  filter::FrameResult step(const StepRecord& record, const filter::PreparedFrame& frame,
                           filter::BeliefVolume& previous);
  [[nodiscard]] const filter::BeliefVolume& belief() const { return filter_.belief(); }
  /// Hands the belief to `out` by exchanging storage; the replay resumes before its next step.
  void hand_belief_to(filter::BeliefVolume& out) { std::swap(filter_.belief(), out); }

 private:
  /// The update of a step and the window's move after it.
  filter::FrameResult update(const StepRecord& record, const filter::PreparedFrame& frame);

  filter::FilterConfig config_;
  RegionWindow window_;
  filter::SeqLocFilter filter_;
};

}  // namespace seqloc::pipeline
