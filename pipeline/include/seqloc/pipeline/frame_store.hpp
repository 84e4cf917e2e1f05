#pragma once
// A route's prepared frames, made once and shared by every mode that runs on the route.

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <vector>

#include "seqloc/filter/seqloc_filter.hpp"
#include "seqloc/pipeline/localize.hpp"

namespace seqloc::pipeline {

/// The frames of one route, each made once by `source` (the built-in matcher, or a .npy read and
/// prepared) and handed to `readers` consumers (the modes running on the route, side by side in
/// any order). Frame i is made by the first consumer that asks for it; one that asks while another
/// makes it makes a later frame meanwhile, or waits. Between the first and the last consumer the
/// frame is held as float16 log-probabilities (half the filter's float32; NumPy's rounding): in
/// memory while the store's frames fit `memory_budget_bytes`, beyond that in a memory-mapped
/// temporary file in `spill_dir` that is unlinked as soon as it is created, so that nothing is
/// left behind on any way out. The last consumer's take releases the frame.
///
/// Every consumer receives the same values, the float16 ones, so a mode gives the same poses
/// whether it runs alone or beside others. A frame asked for more than `readers` times is made
/// again. An error of `source` reaches the consumer that asks for that frame (each one that does).
class FrameStore {
 public:
  struct Stats {
    std::size_t made = 0;          ///< calls of source, remakes included
    std::size_t remade = 0;        ///< frames made again after their last reader released them
    std::size_t spilled = 0;       ///< frames that went to the temporary file
    std::size_t peak_memory_bytes = 0;  ///< largest float16 bytes held in memory at once
  };

  FrameStore(FrameSource source, std::size_t frames, int readers, std::size_t memory_budget_bytes,
             std::filesystem::path spill_dir = {});
  ~FrameStore();
  FrameStore(const FrameStore&) = delete;
  FrameStore& operator=(const FrameStore&) = delete;

  /// Frame i for one consumer (thread-safe); throws what the source throws for frame i.
  [[nodiscard]] std::shared_ptr<const filter::PreparedFrame> take(std::size_t i);
  /// A FrameSource taking from this store (which must outlive it).
  [[nodiscard]] FrameSource source() {
    return [this](std::size_t i) { return take(i); };
  }
  [[nodiscard]] Stats stats() const;

 private:
  class SpillFile;
  enum class State { empty, making, ready };
  struct Slot {
    State state = State::empty;
    int taken = 0, copying = 0;  ///< consumers that took it, and that are copying it out
    bool released = false;
    filter::PreparedFrame header;  ///< everything but the log-probabilities
    /// The frame as made (its values rounded), for the first consumer: the others convert the
    /// float16 copy back.
    std::shared_ptr<const filter::PreparedFrame> made;
    std::vector<std::uint16_t> memory;
    std::uint16_t* mapped = nullptr;
    std::size_t mapped_offset = 0, mapped_bytes = 0;
  };

  /// Makes frame i into its slot (whose state the caller set to making; lock held on entry and
  /// exit, released while making).
  void make(std::size_t i, std::unique_lock<std::mutex>& lock);
  void release(Slot& slot);
  /// Releases the slot once its last reader took it and no one is copying it out (lock held).
  void release_if_done(Slot& slot);

  FrameSource source_;
  int readers_;
  std::size_t budget_;
  std::filesystem::path spill_dir_;
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<Slot> slots_;
  std::unique_ptr<SpillFile> spill_;
  std::size_t memory_bytes_ = 0;
  Stats stats_;
};

/// What a frame becomes in a FrameStore: its log-probabilities rounded to float16 (NumPy's
/// rounding) and its entropy, peak and argmax those of the rounded values. A loop that feeds
/// frames itself applies this to get localize's poses exactly. Returns the float16 bits the
/// values now hold (what the store keeps), or nothing where `keep_halves` is false.
std::vector<std::uint16_t> round_like_frame_store(filter::PreparedFrame& frame, bool keep_halves = true);

}  // namespace seqloc::pipeline
