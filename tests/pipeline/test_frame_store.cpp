// FrameStore: each frame made once for all its readers, the same float16 values in memory and in
// the spill file, nothing left on disk, errors reaching whoever asks for the bad frame.

#include <atomic>
#include <cmath>
#include <filesystem>
#include <limits>
#include <random>
#include <stdexcept>
#include <thread>
#include <vector>

#include <gtest/gtest.h>

#include "seqloc/core/error.hpp"
#include "seqloc/io/npy.hpp"
#include "seqloc/pipeline/frame_store.hpp"
#include "support/test_support.hpp"

namespace seqloc::pipeline::frame_store_tests {
namespace {

constexpr int kH = 6, kW = 7, kBins = 8;

filter::PreparedFrame random_frame(std::size_t i) {
  filter::PreparedFrame f;
  f.height = kH;
  f.width = kW;
  f.bins = kBins;
  f.log_cells = std::log(static_cast<double>(kH * kW * kBins));
  f.entropy = 0.5 + 0.01 * static_cast<double>(i);
  f.max_log_prob = -1.25f;
  f.argmax_v = 1, f.argmax_u = 2, f.argmax_bin = static_cast<int>(i % kBins);
  std::mt19937 rng(static_cast<unsigned>(i));
  std::uniform_real_distribution<float> value(-20.0f, 0.0f);
  f.log_prob.resize(static_cast<std::size_t>(kH * kW * kBins));
  for (auto& v : f.log_prob) v = value(rng);
  f.log_prob[3] = -std::numeric_limits<float>::infinity();
  return f;
}

// A source counting its calls; frame `bad` (if any) throws.
struct CountingSource {
  std::shared_ptr<std::atomic<int>> calls = std::make_shared<std::atomic<int>>(0);
  std::size_t bad = static_cast<std::size_t>(-1);
  FrameSource source() const {
    return [calls = calls, bad = bad](std::size_t i) {
      ++*calls;
      if (i == bad) throw DataError("frame " + std::to_string(i) + " is bad");
      return std::make_shared<const filter::PreparedFrame>(random_frame(i));
    };
  }
};

// The frame as the store holds it: its values in float16, and its entropy, peak and argmax those
// of the rounded values (what the filter multiplies in), not the source's.
void expect_half_of(const filter::PreparedFrame& got, std::size_t i) {
  auto want = random_frame(i);
  const float source_max = want.max_log_prob;
  round_like_frame_store(want);
  EXPECT_NE(want.max_log_prob, source_max) << "the source's own summary must not be what is kept";
  EXPECT_EQ(got.height, want.height);
  EXPECT_EQ(got.bins, want.bins);
  EXPECT_EQ(got.entropy, want.entropy);
  EXPECT_EQ(got.argmax_bin, want.argmax_bin);
  EXPECT_EQ(got.max_log_prob, want.max_log_prob);
  ASSERT_EQ(got.log_prob.size(), want.log_prob.size());
  for (std::size_t k = 0; k < want.log_prob.size(); ++k) {
    ASSERT_EQ(got.log_prob[k], filter::half_to_float(filter::float_to_half(want.log_prob[k]))) << i << " " << k;
  }
}

// Four readers in four threads, each taking every frame once in its own order.
void four_readers(FrameStore& store, std::size_t frames) {
  std::vector<std::jthread> readers;
  readers.reserve(4);
  for (int r = 0; r < 4; ++r) {
    readers.emplace_back([&store, frames, r] {
      std::vector<std::size_t> order(frames);
      for (std::size_t i = 0; i < frames; ++i) order[i] = r % 2 ? frames - 1 - i : i;
      for (std::size_t i : order) expect_half_of(*store.take(i), i);
    });
  }
}

TEST(FrameStore, EachFrameIsMadeOnceForAllItsReaders) {
  CountingSource counting;
  constexpr std::size_t kFrames = 12;
  FrameStore store(counting.source(), kFrames, 4, std::size_t{1} << 30);
  four_readers(store, kFrames);
  EXPECT_EQ(*counting.calls, static_cast<int>(kFrames));
  const auto stats = store.stats();
  EXPECT_EQ(stats.made, kFrames);
  EXPECT_EQ(stats.remade, 0u);
  EXPECT_EQ(stats.spilled, 0u);
  EXPECT_GT(stats.peak_memory_bytes, 0u);
}

TEST(FrameStore, BeyondTheBudgetFramesGoToAFileThatNoDirectoryShows) {
  test::ScratchDir spill;
  CountingSource counting;
  constexpr std::size_t kFrames = 10;
  const std::size_t one_frame = static_cast<std::size_t>(kH * kW * kBins) * 2;
  {
    FrameStore store(counting.source(), kFrames, 4, 2 * one_frame, spill.path());
    four_readers(store, kFrames);
    EXPECT_EQ(*counting.calls, static_cast<int>(kFrames));
    EXPECT_GT(store.stats().spilled, 0u);
    EXPECT_LE(store.stats().peak_memory_bytes, 2 * one_frame);
    // Spilled and taken by one of its two readers: the frame is in the file, the file nowhere.
    FrameStore held(counting.source(), 3, 2, 0, spill.path());
    expect_half_of(*held.take(0), 0);
    EXPECT_EQ(held.stats().spilled, 1u);
    EXPECT_TRUE(std::filesystem::is_empty(spill.path()));
    expect_half_of(*held.take(0), 0);
  }
  EXPECT_TRUE(std::filesystem::is_empty(spill.path()));
  {
    // One reader takes each frame as made: nothing is kept for another, so nothing spills.
    FrameStore alone(counting.source(), 2, 1, 0, spill.path() / "missing");
    expect_half_of(*alone.take(0), 0);
    expect_half_of(*alone.take(1), 1);
    EXPECT_EQ(alone.stats().spilled, 0u);
    EXPECT_EQ(alone.stats().peak_memory_bytes, 0u);
  }
  FrameStore nowhere(counting.source(), 2, 2, 0, spill.path() / "missing");
  try {
    (void)nowhere.take(0);
    FAIL() << "spilling into a missing directory must fail";
  } catch (const seqloc::Error& e) {
    EXPECT_EQ(e.category(), seqloc::ErrorCategory::io);
    EXPECT_NE(std::string(e.what()).find("missing"), std::string::npos) << e.what();
  }
}

TEST(FrameStore, TheLastReaderReleasesAFrameAndALateOneGetsItMadeAgain) {
  CountingSource counting;
  FrameStore store(counting.source(), 3, 2, std::size_t{1} << 30);
  expect_half_of(*store.take(1), 1);
  expect_half_of(*store.take(1), 1);
  EXPECT_EQ(store.stats().remade, 0u);
  expect_half_of(*store.take(1), 1);  // a third reader of two
  EXPECT_EQ(store.stats().remade, 1u);
  EXPECT_EQ(*counting.calls, 2);
  try {
    (void)store.take(3);
    FAIL() << "a frame beyond the route must fail";
  } catch (const seqloc::Error& e) {
    EXPECT_EQ(e.category(), seqloc::ErrorCategory::internal) << e.what();
  }
}

TEST(FrameStore, AnErrorReachesEveryReaderOfThatFrameAndNoOther) {
  CountingSource counting;
  counting.bad = 4;
  constexpr std::size_t kFrames = 8;
  FrameStore store(counting.source(), kFrames, 2, std::size_t{1} << 30);
  std::atomic<int> errors{0};
  {
    std::vector<std::jthread> readers;
    readers.reserve(2);
    for (int r = 0; r < 2; ++r) {
      readers.emplace_back([&] {
        for (std::size_t i = 0; i < kFrames; ++i) {
          try {
            expect_half_of(*store.take(i), i);
          } catch (const DataError& e) {
            EXPECT_EQ(i, 4u);
            EXPECT_STREQ(e.what(), "frame 4 is bad");
            ++errors;
          }
        }
      });
    }
  }
  EXPECT_EQ(errors, 2);
}

}  // namespace
}  // namespace seqloc::pipeline::frame_store_tests
