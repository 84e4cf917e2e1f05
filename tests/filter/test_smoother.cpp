// The two-filter smoother (smoother.hpp) against a brute-force posterior: with exact odometry (whole
// cells, quarter turns), no motion noise and ETU, MGR and self-calibration off, the posterior of
// frame t is the product of every frame's likelihood at the pose the motion chains x to at that
// frame, computed here cell by cell in double from the conventions alone (no filter code).

#include <algorithm>
#include <cmath>
#include <optional>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "seqloc/filter/smoother.hpp"
#include "seqloc/offline/offline.hpp"

namespace seqloc::filter {
namespace {

using offline::offline_poses;
using offline::OfflineAggregator;
using offline::OfflineFrame;

constexpr int kW = 36, kH = 32, kR = 4, kSide = 11;  // 4 headings: quarter turns are whole bins

FilterConfig plain_config() {
  FilterConfig c;
  c.width = kW;
  c.height = kH;
  c.headings = kR;
  c.etu = c.mgr = c.pas = c.self_calibrate = false;
  c.subbin_half_width = 1;  // of 4 bins
  c.threads = 2;
  return c;
}

struct Frame {
  std::vector<float> values;  // (H, W, N) log-probabilities as a backbone writes them
  CropPose crop;
  Odometry odometry;
};

// Pose (u, v, bin) of the vehicle moved by `o` (conventions.md section 1): forward along the
// heading (clockwise from north; u east, v south, 0.5 m cells), then the heading turns by -yaw.
struct Cell {
  int u, v, k;
};
Cell moved(Cell c, const Odometry& o) {
  const double h = c.k * 360.0 / kR * M_PI / 180.0;
  const double east = o.forward_m * std::sin(h) - o.left_m * std::cos(h);
  const double north = o.forward_m * std::cos(h) + o.left_m * std::sin(h);
  const int turn = static_cast<int>(std::lround(o.yaw_deg * kR / 360.0));
  return {c.u + static_cast<int>(std::lround(east / 0.5)), c.v - static_cast<int>(std::lround(north / 0.5)),
          ((c.k - turn) % kR + kR) % kR};
}
Cell moved_back(Cell c, const Odometry& o) {
  // The pose that `o` moves to c: undo the turn, then the displacement at the earlier heading.
  const int turn = static_cast<int>(std::lround(o.yaw_deg * kR / 360.0));
  Cell before{c.u, c.v, ((c.k + turn) % kR + kR) % kR};
  const Cell after = moved(before, o);
  before.u -= after.u - c.u;
  before.v -= after.v - c.v;
  return before;
}

bool in_window(const Cell& c) { return c.u >= 0 && c.u < kW && c.v >= 0 && c.v < kH; }

// log p of frame s at window pose c, normalized over its own cells; log(1/M) - outside_nats where
// its crop does not reach.
double frame_log_likelihood(const Frame& f, const Cell& c, double outside_nats) {
  const int M = kSide * kSide * kR;
  double max = -1e300, sum = 0;
  for (float x : f.values) max = std::max(max, static_cast<double>(x));
  for (float x : f.values) sum += std::exp(x - max);
  const double lse = max + std::log(sum);
  const int vu = c.u - static_cast<int>(f.crop.centre_u) + kSide / 2;
  const int vv = c.v - static_cast<int>(f.crop.centre_v) + kSide / 2;
  if (vu < 0 || vu >= kSide || vv < 0 || vv >= kSide) return -std::log(static_cast<double>(M)) - outside_nats;
  return f.values[static_cast<std::size_t>((vv * kSide + vu) * kR + c.k)] - lse;
}

// A drive of quarter turns and whole-cell moves, crops on the truth, noisy volumes peaked at it.
std::vector<Frame> route(std::uint32_t seed, double peak) {
  const std::vector<Odometry> moves{{0, 0, 0},  {1.0, 0, 0}, {1.5, 0, 90}, {1.0, 0.5, 0},
                                    {0.5, 0, -90}, {1.0, 0, 0}, {0.5, -0.5, 0}};
  std::mt19937 rng(seed);
  std::normal_distribution<float> noise(0.0f, 1.0f);
  std::vector<Frame> frames;
  Cell truth{16, 17, 1};
  for (std::size_t t = 0; t < moves.size(); ++t) {
    if (t > 0) truth = moved(truth, moves[t]);
    Frame f;
    f.values.resize(kSide * kSide * kR);
    for (auto& x : f.values) x = noise(rng);
    f.values[static_cast<std::size_t>(((kSide / 2) * kSide + kSide / 2) * kR + truth.k)] += static_cast<float>(peak);
    f.crop = {static_cast<double>(truth.u), static_cast<double>(truth.v), 0};
    f.odometry = moves[t];
    frames.push_back(std::move(f));
  }
  return frames;
}

PreparedFrame prepared(const Frame& f) {
  return prepare_frame({f.values.data(), VolumeType::float32, VolumeValues::log_prob, kSide, kSide, kR, 0.5}, kR);
}

// The smoother's posterior and result for every frame: forward, then backward.
struct Smoothed {
  std::vector<BeliefVolume> posterior;
  std::vector<FrameResult> results;
};
Smoothed smooth(const std::vector<Frame>& frames, const FilterConfig& config) {
  std::vector<PreparedFrame> prepared_frames;
  for (const auto& f : frames) prepared_frames.push_back(prepared(f));
  SeqLocFilter forward(config);
  forward.reset_uniform();
  std::vector<BeliefVolume> alpha;
  std::vector<FrameWeighting> weighting;
  for (std::size_t t = 0; t < frames.size(); ++t) {
    weighting.push_back(forward.step(prepared_frames[t], frames[t].crop, frames[t].odometry, {}).weighting);
    alpha.push_back(forward.belief());
  }
  BackwardFilter backward(config);
  Smoothed out;
  out.posterior.assign(frames.size(), BeliefVolume(kW, kH, kR));
  out.results.resize(frames.size());
  for (std::size_t t = frames.size(); t-- > 0;) {
    out.results[t] = smoothed_result(alpha[t], backward.belief(), config, &out.posterior[t]);
    backward.absorb(prepared_frames[t], frames[t].crop, weighting[t], {});
    if (t > 0) backward.step_back(frames[t].odometry);
  }
  return out;
}

TEST(Smoother, PosteriorIsTheProductOfEveryFramesAlignedLikelihood) {
  const FilterConfig config = plain_config();
  const auto frames = route(7, 0.5);
  const Smoothed s = smooth(frames, config);
  const auto T = frames.size();
  for (std::size_t t = 0; t < T; ++t) {
    // Brute force over the cells whose chain stays in the window at every frame (elsewhere the
    // filters' windows lose the frames beyond their edge by design).
    std::vector<double> reference(static_cast<std::size_t>(kW * kH * kR), std::nan(""));
    double top = -1e300;
    for (int k = 0; k < kR; ++k)
      for (int v = 0; v < kH; ++v)
        for (int u = 0; u < kW; ++u) {
          double log_sum = 0;
          bool inside = true;
          Cell c{u, v, k};
          for (std::size_t s2 = t + 1; s2 < T && inside; ++s2) {
            c = moved(c, frames[s2].odometry);
            inside = in_window(c);
            log_sum += frame_log_likelihood(frames[s2], c, config.outside_crop_nats);
          }
          c = {u, v, k};
          log_sum += frame_log_likelihood(frames[t], c, config.outside_crop_nats);
          for (std::size_t s2 = t; s2 > 0 && inside; --s2) {
            c = moved_back(c, frames[s2].odometry);
            inside = in_window(c);
            log_sum += frame_log_likelihood(frames[s2 - 1], c, config.outside_crop_nats);
          }
          if (!inside) continue;
          reference[static_cast<std::size_t>((k * kH + v) * kW + u)] = log_sum;
          top = std::max(top, log_sum);
        }
    // Both normalized over those cells.
    double ref_sum = 0, got_sum = 0;
    std::size_t cells = 0;
    for (std::size_t i = 0; i < reference.size(); ++i) {
      if (std::isnan(reference[i])) continue;
      ref_sum += std::exp(reference[i] - top);
      got_sum += s.posterior[t].data()[i];
      ++cells;
    }
    ASSERT_GT(cells, reference.size() / 2) << "frame " << t << ": most of the window is interior";
    // Every cell to float precision: absolutely, and relatively wherever the posterior is within
    // 25 nats of its peak (float products of seven frames: a few ulps each).
    double worst = 0, worst_log = 0, largest = 0;
    std::size_t compared = 0;
    for (std::size_t i = 0; i < reference.size(); ++i) {
      if (std::isnan(reference[i])) continue;
      const double want = std::exp(reference[i] - top) / ref_sum;
      const double got = s.posterior[t].data()[i] / got_sum;
      worst = std::max(worst, std::abs(got - want));
      largest = std::max(largest, want);
      if (reference[i] - top > -25) {
        worst_log = std::max(worst_log, std::abs(std::log(got) - std::log(want)));
        ++compared;
      }
    }
    EXPECT_LT(worst, 1e-6 * largest) << "frame " << t << " (largest posterior " << largest << ")";
    EXPECT_LT(worst_log, 1e-4) << "frame " << t;
    EXPECT_GT(compared, cells / 4) << "frame " << t << ": a spread posterior, compared cell by cell";
  }
}

TEST(Smoother, ArgmaxIsOfflineOverAllFrames) {
  const FilterConfig config = plain_config();
  for (std::uint32_t seed : {1u, 2u, 3u}) {
    const auto frames = route(seed, 2.5);
    const Smoothed s = smooth(frames, config);
    std::vector<PreparedFrame> prepared_frames;
    for (const auto& f : frames) prepared_frames.push_back(prepared(f));
    std::vector<OfflineFrame> offline;
    for (std::size_t t = 0; t < frames.size(); ++t) {
      offline.push_back({&prepared_frames[t], frames[t].crop, frames[t].odometry});
    }
    const auto poses = offline_poses(offline, config, -1);
    for (std::size_t t = 0; t < frames.size(); ++t) {
      EXPECT_EQ(s.results[t].argmax.u, poses[t].u) << "seed " << seed << " frame " << t;
      EXPECT_EQ(s.results[t].argmax.v, poses[t].v) << "seed " << seed << " frame " << t;
      EXPECT_EQ(s.results[t].argmax.heading_deg, poses[t].heading_deg) << "seed " << seed << " frame " << t;
    }
  }
}

TEST(Smoother, TheLastFrameIsTheForwardFiltersAndTheFirstSeesTheWholeRoute) {
  FilterConfig config = plain_config();
  config.pas = true;
  const auto frames = route(5, 1.0);
  const Smoothed s = smooth(frames, config);
  // beta is uniform at the last frame: the smoothed result is the filter's own.
  SeqLocFilter forward(config);
  forward.reset_uniform();
  FrameResult first, last;
  for (const auto& f : frames) {
    last = forward.step(prepared(f), f.crop, f.odometry, {});
    if (&f == &frames.front()) first = last;
  }
  EXPECT_EQ(s.results.back().argmax.u, last.argmax.u);
  EXPECT_EQ(s.results.back().argmax.v, last.argmax.v);
  EXPECT_NEAR(s.results.back().pose.u, last.pose.u, 1e-9);
  EXPECT_NEAR(s.results.back().pose.v, last.pose.v, 1e-9);
  // The first frame's posterior is far sharper than its filtered belief: every later frame counts.
  EXPECT_GT(s.results.front().peak_log_belief, first.peak_log_belief + 1.0);
  const BeliefVolume a(kW, kH, kR);
  EXPECT_THROW((void)smoothed_result(a, BeliefVolume(kW, kH, 8), config), FilterError);
  // Passes certain of different places share no mass: the forward belief alone decides.
  BeliefVolume here(kW, kH, kR), there(kW, kH, kR);
  std::fill(here.data(), here.data() + here.size(), 0.0f);
  std::fill(there.data(), there.data() + there.size(), 0.0f);
  here.prob(5, 6, 1) = 1;
  there.prob(20, 21, 3) = 1;
  const FrameResult apart = smoothed_result(here, there, config);
  EXPECT_EQ(apart.argmax.u, 5);
  EXPECT_EQ(apart.argmax.v, 6);
  EXPECT_EQ(apart.argmax.heading_deg, 90);
  EXPECT_EQ(apart.pose.u, 5) << "PAS on the forward belief alone";
}

}  // namespace
}  // namespace seqloc::filter
