#pragma once
// A route's prepared frames as one mode takes them, in order: frame i from the source, and with
// lookahead the next frame prepared on a background task while the mode works on frame i.

#include <cstddef>
#include <functional>
#include <future>
#include <map>
#include <memory>

#include "seqloc/filter/seqloc_filter.hpp"

namespace seqloc::pipeline {

/// Where frame i's prepared (normalized) volume comes from. Called from a background task as
/// well as from the calling thread, never twice at once.
using FrameSource = std::function<std::shared_ptr<const filter::PreparedFrame>(std::size_t frame)>;

class FramePrefetcher {
 public:
  /// `frames`: the route's length. With `lookahead`, get(i) starts preparing frame i + 1.
  FramePrefetcher(FrameSource source, std::size_t frames, bool lookahead);
  FramePrefetcher(const FramePrefetcher&) = delete;
  FramePrefetcher& operator=(const FramePrefetcher&) = delete;
  /// Waits for a frame still being prepared (its error is dropped: the caller has its own).
  ~FramePrefetcher();

  /// Frame i, kept until released. Rethrows the source's error for frame i.
  [[nodiscard]] const filter::PreparedFrame& get(std::size_t i) { return *get_shared(i); }
  /// The same, shared with the caller (who may keep it after release).
  [[nodiscard]] std::shared_ptr<const filter::PreparedFrame> get_shared(std::size_t i);
  /// Starts preparing frame i in the background (unless it is kept or on its way): for a caller
  /// that knows its next frame is not the following one. A frame prefetched and never taken costs
  /// its source one more read.
  void prefetch(std::size_t i);
  /// Turns the automatic preparation of frame i + 1 on or off.
  void set_lookahead(bool on) { lookahead_ = on; }
  void release(std::size_t i) { kept_.erase(i); }
  /// Releases every frame before i.
  void release_before(std::size_t i) { kept_.erase(kept_.begin(), kept_.lower_bound(i)); }

  /// Seconds spent reading and preparing frames (in the background or not), and seconds get()
  /// waited for a frame being prepared in the background.
  [[nodiscard]] double prepare_seconds() const { return prepare_seconds_; }
  [[nodiscard]] double wait_seconds() const { return wait_seconds_; }

 private:
  using Frame = std::shared_ptr<const filter::PreparedFrame>;
  Frame load(std::size_t i, double* seconds) const;

  FrameSource source_;
  std::size_t frames_;
  bool lookahead_;
  std::map<std::size_t, Frame> kept_;
  double prepare_seconds_ = 0, wait_seconds_ = 0;
  std::size_t next_index_ = 0;
  double next_seconds_ = 0;
  std::future<Frame> next_;  ///< frame next_index_, being prepared (destroyed first: it uses the members above)
};

}  // namespace seqloc::pipeline
