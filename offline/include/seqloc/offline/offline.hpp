#pragma once
// The "offline" baseline (conventions.md section 6): for each frame t, the sum of the
// log-likelihoods of frames s (all of them, or |s - t| <= K) warped into frame t's pose space by
// the relative motion between s and t; its argmax is frame t's pose. It uses future frames, so
// it is an upper reference for what sequence aggregation can reach, not an online method.
// Frames are placed and warped as probabilities (log-probabilities interpolated across a peak's
// edge give log(0)); a cell a frame does not observe adds log(1/M) - outside_crop_nats (the
// online filter's rule, FilterConfig); the argmax is sought among
// the cells frame t observes.

#include <cstdint>
#include <memory>
#include <vector>

#include "seqloc/filter/config.hpp"
#include "seqloc/filter/seqloc_filter.hpp"

namespace seqloc::offline {

using filter::CropPose;
using filter::FilterConfig;
using filter::Odometry;
using filter::Pose;
using filter::PreparedFrame;

struct OfflineFrame {
  const PreparedFrame* frame = nullptr;
  CropPose crop;
  Odometry from_previous;  ///< motion from the previous frame (ignored for the first)
  /// OfflineAggregator keeps the frame's placement under this key (>= 0, e.g. its index in the
  /// route) from one pose to the next; < 0: placed for one pose only.
  std::int64_t key = -1;
};

/// The offline poses of a route frame after frame, with each frame placed once (its probabilities
/// resampled at every window heading on a canvas over its crop) rather than once per frame and
/// neighbour: a placement is kept under the frame's key while the frame stays in range, and
/// serves again when the window moved by whole cells. The sum of frame t is formed only over the
/// cells of t's own crop (where its argmax is sought). Every frame in range counts whole, wherever
/// its crop lies: the window bounds only where t's pose is sought, not which evidence is summed.
class OfflineAggregator {
 public:
  explicit OfflineAggregator(const FilterConfig& config);
  ~OfflineAggregator();
  OfflineAggregator(OfflineAggregator&&) noexcept;
  OfflineAggregator& operator=(OfflineAggregator&&) noexcept;
  OfflineAggregator(const OfflineAggregator&) = delete;
  OfflineAggregator& operator=(const OfflineAggregator&) = delete;

  /// The pose of frame t from the frames s with |s - t| <= half_window (all when < 0), their
  /// crops given in the cells of a window of the config (the caller may centre one on frame t;
  /// other frames' crops may lie beyond it).
  [[nodiscard]] Pose pose_at(const std::vector<OfflineFrame>& frames, std::size_t t, int half_window = -1);

 private:
  struct Canvas;
  struct Impl;
  [[nodiscard]] Canvas place(const OfflineFrame& frame);
  FilterConfig config_;
  std::unique_ptr<Impl> impl_;
};

/// The pose of frame `t` alone: the frames' crops must be given in the cells of a window of
/// `config` (the caller may centre one on frame t; other crops may lie beyond it); frames s with
/// |s - t| <= half_window (all when < 0) count.
[[nodiscard]] Pose offline_pose_at(const std::vector<OfflineFrame>& frames, std::size_t t, const FilterConfig& config,
                                   int half_window = -1);

/// One pose per frame, in the window of `config` (width, height, headings, threads).
/// `half_window` < 0 aggregates all frames.
[[nodiscard]] std::vector<Pose> offline_poses(std::vector<OfflineFrame> frames, const FilterConfig& config,
                                              int half_window = -1);

}  // namespace seqloc::offline
