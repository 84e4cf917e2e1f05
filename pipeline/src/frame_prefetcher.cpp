#include "seqloc/pipeline/frame_prefetcher.hpp"

#include "seqloc/core/stopwatch.hpp"

namespace seqloc::pipeline {

using core::Clock;
using core::seconds_since;

FramePrefetcher::FramePrefetcher(FrameSource source, std::size_t frames, bool lookahead)
    : source_(std::move(source)), frames_(frames), lookahead_(lookahead) {}

FramePrefetcher::~FramePrefetcher() {
  if (next_.valid()) next_.wait();
}

FramePrefetcher::Frame FramePrefetcher::load(std::size_t i, double* seconds) const {
  const auto t0 = Clock::now();
  auto frame = source_(i);
  *seconds = seconds_since(t0);
  return frame;
}

std::shared_ptr<const filter::PreparedFrame> FramePrefetcher::get_shared(std::size_t i) {
  auto it = kept_.find(i);
  if (it == kept_.end()) {
    Frame frame;
    if (next_.valid() && next_index_ == i) {
      const auto t0 = Clock::now();
      frame = next_.get();  // rethrows the volume's error, in frame order
      wait_seconds_ += seconds_since(t0);
      prepare_seconds_ += next_seconds_;
    } else {
      double seconds = 0;
      frame = load(i, &seconds);
      prepare_seconds_ += seconds;
    }
    it = kept_.emplace(i, std::move(frame)).first;
  }
  // Start on the following frame while the caller works on this one.
  if (lookahead_ && i + 1 < frames_) prefetch(i + 1);
  return it->second;
}

void FramePrefetcher::prefetch(std::size_t i) {
  if (i >= frames_ || kept_.count(i) != 0 || (next_.valid() && next_index_ == i)) return;
  if (next_.valid()) next_.wait();  // a frame nobody took (not in order); never two at once
  next_index_ = i;
  next_ = std::async(std::launch::async, [this, i] { return load(i, &next_seconds_); });
}

}  // namespace seqloc::pipeline
