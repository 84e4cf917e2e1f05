#include "seqloc/pipeline/frame_store.hpp"

#include <sys/mman.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstdlib>
#include <cstring>
#include <map>
#include <span>
#include <stdexcept>
#include <string>
#include <system_error>

#include "seqloc/core/error.hpp"
#include "seqloc/core/files.hpp"

namespace seqloc::pipeline {
namespace {

// How far past the frame it waits for a consumer makes frames while another consumer makes that
// one: enough to keep a second core busy, few enough not to run ahead of the modes.
constexpr std::size_t kLookahead = 2;

std::size_t values_of(const filter::PreparedFrame& f) {
  return static_cast<std::size_t>(f.bins) * static_cast<std::size_t>(f.height) * static_cast<std::size_t>(f.width);
}

}  // namespace

// An unlinked temporary file holding spilled frames, each in its own page-aligned mapping. Freed
// extents are reused by later frames of the same size.
class FrameStore::SpillFile {
 public:
  explicit SpillFile(const std::filesystem::path& dir) : dir_(dir) {
    fd_ = core::open_unlinked_file(dir, "seqloc-frames");  // the space is freed when fd_ closes
    if (fd_ < 0) fail("cannot create a temporary file");
  }
  ~SpillFile() { ::close(fd_); }
  SpillFile(const SpillFile&) = delete;
  SpillFile& operator=(const SpillFile&) = delete;

  // A writable mapping of `bytes` (rounded up to pages); returns its offset in the file.
  std::uint16_t* map(std::size_t bytes, std::size_t& offset, std::size_t& mapped_bytes) {
    const auto page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
    mapped_bytes = (bytes + page - 1) / page * page;
    auto reuse = free_.find(mapped_bytes);
    if (reuse != free_.end()) {
      offset = reuse->second;
      free_.erase(reuse);
    } else {
      offset = end_;
      if (::ftruncate(fd_, static_cast<off_t>(end_ + mapped_bytes)) != 0) fail("cannot grow the temporary file");
      end_ += mapped_bytes;
    }
    void* p = ::mmap(nullptr, mapped_bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd_, static_cast<off_t>(offset));
    if (p == MAP_FAILED) {
      free_.emplace(mapped_bytes, offset);
      fail("cannot map the temporary file");
    }
    return static_cast<std::uint16_t*>(p);
  }

  void unmap(std::uint16_t* p, std::size_t offset, std::size_t mapped_bytes) {
    ::munmap(p, mapped_bytes);
    free_.emplace(mapped_bytes, offset);
  }

 private:
  [[noreturn]] void fail(const std::string& what) const {
    const int error = errno;
    throw IoError("frame store: " + what + " in " + dir_.string() +
                  " (spilling frames beyond the memory budget): " + std::generic_category().message(error));
  }

  std::filesystem::path dir_;
  int fd_ = -1;
  std::size_t end_ = 0;
  std::multimap<std::size_t, std::size_t> free_;  // bytes -> offset
};

FrameStore::FrameStore(FrameSource source, std::size_t frames, int readers, std::size_t memory_budget_bytes,
                       std::filesystem::path spill_dir)
    : source_(std::move(source)),
      readers_(std::max(1, readers)),
      budget_(memory_budget_bytes),
      spill_dir_(spill_dir.empty() ? std::filesystem::temp_directory_path() : std::move(spill_dir)),
      slots_(frames) {}

FrameStore::~FrameStore() {
  for (auto& slot : slots_) release(slot);
}

void FrameStore::release(Slot& slot) {
  if (slot.mapped != nullptr) {
    spill_->unmap(slot.mapped, slot.mapped_offset, slot.mapped_bytes);
    slot.mapped = nullptr;
  }
  memory_bytes_ -= slot.memory.size() * sizeof(std::uint16_t);
  std::vector<std::uint16_t>().swap(slot.memory);
  slot.made.reset();
}

std::vector<std::uint16_t> round_like_frame_store(filter::PreparedFrame& frame, bool keep_halves) {
  const std::size_t n = frame.log_prob.size();
  std::vector<std::uint16_t> halves(keep_halves ? n : 0);
  // A block at a time, so that the values are read back while in cache: into the halves kept, or
  // through a buffer.
  constexpr std::size_t kBlock = 8192;
  std::uint16_t block[kBlock];
  for (std::size_t at = 0; at < n; at += kBlock) {
    const std::size_t len = std::min(kBlock, n - at);
    const std::span<float> values(frame.log_prob.data() + at, len);
    const std::span<std::uint16_t> bits(keep_halves ? halves.data() + at : block, len);
    filter::floats_to_halves(values, bits);
    filter::halves_to_floats(bits, values);
  }
  filter::summarize_frame(frame);
  return halves;
}

void FrameStore::make(std::size_t i, std::unique_lock<std::mutex>& lock) {
  Slot& slot = slots_[i];
  const bool again = slot.released;
  lock.unlock();
  std::shared_ptr<const filter::PreparedFrame> frame;
  std::vector<std::uint16_t> halves;
  try {
    // The header describes the rounded values (their entropy, peak and argmax), so that a frame
    // written out as float16 and read back is the same frame. A frame the source no longer holds
    // is rounded where it lies; with one consumer no float16 copy is kept (it takes this frame).
    std::shared_ptr<const filter::PreparedFrame> source_frame = source_(i);
    auto rounded = source_frame.use_count() == 1 ? std::const_pointer_cast<filter::PreparedFrame>(source_frame)
                                                 : std::make_shared<filter::PreparedFrame>(*source_frame);
    source_frame.reset();
    halves = round_like_frame_store(*rounded, readers_ > 1);
    if (readers_ > 1 && halves.size() != values_of(*rounded)) {
      throw Error(ErrorCategory::internal, "frame store: frame " + std::to_string(i) + " holds " +
                                               std::to_string(halves.size()) + " values for its shape's " +
                                               std::to_string(values_of(*rounded)));
    }
    frame = std::move(rounded);
  } catch (...) {
    lock.lock();
    slot.state = State::empty;
    changed_.notify_all();
    throw;
  }
  lock.lock();
  filter::PreparedFrame& h = slot.header;
  h.height = frame->height;
  h.width = frame->width;
  h.bins = frame->bins;
  h.cell_m = frame->cell_m;
  h.log_cells = frame->log_cells;
  h.entropy = frame->entropy;
  h.max_log_prob = frame->max_log_prob;
  h.argmax_v = frame->argmax_v;
  h.argmax_u = frame->argmax_u;
  h.argmax_bin = frame->argmax_bin;
  const std::size_t bytes = halves.size() * sizeof(std::uint16_t);
  slot.made = std::move(frame);
  try {
    if (bytes == 0) {
      // one consumer: it takes the frame as made
    } else if (memory_bytes_ + bytes <= budget_) {
      slot.memory = std::move(halves);
      memory_bytes_ += bytes;
      stats_.peak_memory_bytes = std::max(stats_.peak_memory_bytes, memory_bytes_);
    } else {
      if (!spill_) spill_ = std::make_unique<SpillFile>(spill_dir_);
      slot.mapped = spill_->map(bytes, slot.mapped_offset, slot.mapped_bytes);
      std::memcpy(slot.mapped, halves.data(), bytes);
      ++stats_.spilled;
    }
  } catch (...) {
    slot.state = State::empty;
    changed_.notify_all();
    throw;
  }
  slot.state = State::ready;
  slot.taken = 0;
  slot.released = false;
  ++stats_.made;
  if (again) ++stats_.remade;
  changed_.notify_all();
}

std::shared_ptr<const filter::PreparedFrame> FrameStore::take(std::size_t i) {
  std::unique_lock lock(mutex_);
  if (i >= slots_.size()) {
    throw Error(ErrorCategory::internal,
                "frame store: frame " + std::to_string(i) + " of " + std::to_string(slots_.size()));
  }
  Slot& slot = slots_[i];
  while (slot.state != State::ready) {
    if (slot.state == State::empty) {
      slot.state = State::making;
      make(i, lock);  // an error goes to this consumer
      continue;
    }
    // Another consumer makes frame i: make a later one meanwhile if one is due, else wait.
    std::size_t j = i + 1;
    const std::size_t last = std::min(slots_.size(), i + 1 + kLookahead);
    while (j < last && (slots_[j].state != State::empty || slots_[j].released)) ++j;
    if (j < last) {
      slots_[j].state = State::making;
      try {
        make(j, lock);
      } catch (...) {  // the consumer that asks for frame j meets this error
      }
    } else {
      changed_.wait(lock);
    }
  }
  if (slot.made) {  // the first consumer
    std::shared_ptr<const filter::PreparedFrame> frame = std::move(slot.made);
    ++slot.taken;
    release_if_done(slot);
    return frame;
  }
  auto frame = std::make_shared<filter::PreparedFrame>(slot.header);
  const std::uint16_t* halves = slot.mapped != nullptr ? slot.mapped : slot.memory.data();
  ++slot.taken;
  ++slot.copying;
  lock.unlock();
  frame->log_prob.resize(values_of(*frame));
  filter::halves_to_floats({halves, frame->log_prob.size()}, frame->log_prob);
  lock.lock();
  --slot.copying;
  release_if_done(slot);
  return frame;
}

void FrameStore::release_if_done(Slot& slot) {
  if (slot.taken < readers_ || slot.copying != 0) return;
  release(slot);
  slot.state = State::empty;
  slot.released = true;
}

FrameStore::Stats FrameStore::stats() const {
  std::lock_guard lock(mutex_);
  return stats_;
}

}  // namespace seqloc::pipeline
