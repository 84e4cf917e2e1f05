// The frame intake (intake/frame.hpp): checks, normalization against a double-precision
// reference, float16 against float32, every vector width, tempering.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "seqloc/intake/frame.hpp"
#include "support/volumes.hpp"

namespace seqloc::intake {
namespace {

using core::FrameVolume;
using core::half_to_float;
using core::VolumeType;
using core::VolumeValues;

using test::random_volume;
using test::Volume;

TEST(Analytic, TemperingIsThePoweredVolumeRenormalized) {
  // Reference: the volume raised to k in the file's own terms (k log p), prepared from scratch.
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> logit(-6.0f, 0.0f);
  Volume raw;
  raw.values.resize(9 * 11 * 16);
  for (auto& x : raw.values) x = logit(rng);
  raw.values[5] = -std::numeric_limits<float>::infinity();  // a zero stays a zero
  const auto base = prepare_frame(raw.view(9, 11, 16), 16);
  for (const double k : {0.25, 1.0, 4.0}) {
    Volume powered = raw;
    for (auto& x : powered.values) x = static_cast<float>(k * x);
    const auto expected = prepare_frame(powered.view(9, 11, 16), 16);
    const auto got = temper_frame(base, k, 2);
    ASSERT_EQ(got.log_prob.size(), expected.log_prob.size());
    for (std::size_t i = 0; i < got.log_prob.size(); ++i) ASSERT_NEAR(got.log_prob[i], expected.log_prob[i], 2e-4) << i;
    EXPECT_NEAR(got.entropy, expected.entropy, 1e-5) << k;
    EXPECT_EQ(got.argmax_v, expected.argmax_v);
    EXPECT_EQ(got.argmax_u, expected.argmax_u);
    EXPECT_EQ(got.argmax_bin, expected.argmax_bin);
  }
  EXPECT_LT(temper_frame(base, 4.0).entropy, base.entropy) << "sharper";
  EXPECT_GT(temper_frame(base, 0.25).entropy, base.entropy) << "flatter";
  EXPECT_THROW((void)temper_frame(base, 0.0), IntakeError);
  EXPECT_THROW((void)temper_frame(base, std::numeric_limits<double>::infinity()), IntakeError);
}

TEST(Intake, BadVolumesAreClearErrors) {
  Volume v;
  v.values.assign(9 * 11 * 16, -1.0f);
  auto expect_error = [](const FrameVolume& view, const std::string& fragment) {
    try {
      (void)prepare_frame(view, 16);
      FAIL() << "no error, expected '" << fragment << "'";
    } catch (const IntakeError& e) {
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
    }
  };
  Volume nan = v;
  nan.values[100] = std::nanf("");
  expect_error(nan.view(9, 11, 16), "NaN at cell 100");
  Volume pinf = v;
  pinf.values[7] = std::numeric_limits<float>::infinity();
  expect_error(pinf.view(9, 11, 16), "+inf");
  Volume negative = v;
  for (auto& x : negative.values) x = 0.5f;
  negative.values[3] = -0.1f;
  FrameVolume prob = negative.view(9, 11, 16);
  prob.values = VolumeValues::prob;
  expect_error(prob, "probability");
  Volume zeros = v;
  std::fill(zeros.values.begin(), zeros.values.end(), 0.0f);
  FrameVolume zero_prob = zeros.view(9, 11, 16);
  zero_prob.values = VolumeValues::prob;
  expect_error(zero_prob, "no probability mass");
  expect_error(v.view(9, 11, 12), "neither divide nor are a multiple");
  expect_error(FrameVolume{}, "empty volume");
}

/// A log-probability volume of h x w x n cells, as float16 (`halves`) or float32 (`floats`).
FrameVolume log_prob_view(const std::vector<float>& floats, const std::vector<std::uint16_t>& halves, bool half, int h,
                          int w, int n) {
  return {half ? static_cast<const void*>(halves.data()) : floats.data(),
          half ? VolumeType::float16 : VolumeType::float32,
          VolumeValues::log_prob,
          h,
          w,
          n,
          0.5};
}

/// The float16 of each value (core::floats_to_halves).
std::vector<std::uint16_t> halves_of(const std::vector<float>& floats) {
  std::vector<std::uint16_t> halves(floats.size());
  core::floats_to_halves(floats, halves);
  return halves;
}

// A NaN or +inf anywhere (a volume's first and last cell, a partial vector's last lane, a row whose
// values rise far above the rows before it, the first row, which the sums take twice) is named by
// its cell at every vector width, in float16 and float32, raised to a power or not; -inf is a zero.
// The vectorized loops find it in their sums, not by testing each value.
TEST(Intake, EveryBadValueIsNamedAtEveryVectorWidth) {
  struct Restore {
    ~Restore() { (void)limit_intake_vector_lanes(16); }
  } restore;
  constexpr int h = 6, w = 16, n = 40;  // 40 bins: two whole vectors of 16 and a partial one
  constexpr std::size_t cells = static_cast<std::size_t>(h) * w * n;
  std::vector<float> base(cells);
  for (std::size_t i = 0; i < cells; ++i) {
    base[i] = -5.0f - static_cast<float>(i % 7) + (i / (static_cast<std::size_t>(w) * n) == 4 ? 60.0f : 0.0f);
  }
  const float nan = std::numeric_limits<float>::quiet_NaN(), inf = std::numeric_limits<float>::infinity();
  for (const std::size_t at : {std::size_t{0}, std::size_t{n - 1}, std::size_t{3 * w * n + 5 * n + 33},
                               std::size_t{4 * w * n + 7}, cells - 1}) {
    for (const float bad : {nan, inf}) {
      std::vector<float> floats = base;
      floats[at] = bad;
      const std::vector<std::uint16_t> halves = halves_of(floats);
      for (const bool half : {false, true}) {
        const FrameVolume volume = log_prob_view(floats, halves, half, h, w, n);
        for (const int lanes : {16, 8, 1}) {
          (void)limit_intake_vector_lanes(lanes);
          for (const double power : {1.0, 2.5}) {
            try {
              (void)prepare_frame(volume, n, 2, power);
              ADD_FAILURE() << "no error for " << bad << " at cell " << at << ", lanes " << lanes;
            } catch (const IntakeError& e) {
              const std::string expected =
                  (std::isnan(bad) ? "NaN" : "log-probability +inf") + std::string(" at cell ") + std::to_string(at);
              EXPECT_NE(std::string(e.what()).find(expected), std::string::npos)
                  << e.what() << " (lanes " << lanes << ", half " << half << ", power " << power << ")";
            }
          }
        }
      }
      floats[at] = 1e37f;  // finite, but out of float's range raised to 40
      for (const int lanes : {16, 8, 1}) {
        (void)limit_intake_vector_lanes(lanes);
        try {
          (void)prepare_frame(log_prob_view(floats, {}, false, h, w, n), n, 1, 40.0);
          ADD_FAILURE() << "no error for 1e37 raised to 40, lanes " << lanes;
        } catch (const IntakeError& e) {
          EXPECT_NE(std::string(e.what()).find("leaves float's range"), std::string::npos) << e.what();
        }
      }
      floats[at] = -inf;  // a zero, not an error
      (void)limit_intake_vector_lanes(16);
      EXPECT_NO_THROW((void)prepare_frame(log_prob_view(floats, {}, false, h, w, n), n, 1, 2.5));
    }
  }
}

// On a shape the vectorized intake writes from the volume directly (16 cells a row, bins in
// eights) and on one it does not.
class Float16Intake : public ::testing::TestWithParam<std::array<int, 3>> {};

TEST_P(Float16Intake, Float16EqualsFloat32AndProbEqualsLogProb) {
  const auto [H, W, N] = GetParam();
  std::mt19937 rng(8);
  const Volume f32 = random_volume(rng, H, W, N);
  // float16 values of exactly representable numbers (multiples of 1/64 in range).
  std::vector<float> exact(f32.values.size());
  std::vector<std::uint16_t> halves(f32.values.size());
  for (std::size_t i = 0; i < exact.size(); ++i) {
    const int q = static_cast<int>(std::lround(f32.values[i] * 64));
    exact[i] = static_cast<float>(q) / 64.0f;
    // Build the half: sign, exponent, mantissa of q / 64.
    std::uint16_t h = 0;
    if (q != 0) {
      const int a = std::abs(q);
      int e = 0;
      while ((a >> (e + 1)) != 0) ++e;  // a in [2^e, 2^(e+1))
      const int mantissa = ((a << 10) >> e) & 0x3FF;
      h = static_cast<std::uint16_t>(((q < 0) << 15) | ((e - 6 + 15) << 10) | mantissa);
    }
    halves[i] = h;
    ASSERT_EQ(half_to_float(h), exact[i]) << i;
  }
  FrameVolume a{exact.data(), VolumeType::float32, VolumeValues::log_prob, H, W, N, 0.5};
  FrameVolume b{halves.data(), VolumeType::float16, VolumeValues::log_prob, H, W, N, 0.5};
  EXPECT_EQ(prepare_frame(a, 16).log_prob, prepare_frame(b, 16).log_prob);
  std::vector<float> probs(exact.size());
  for (std::size_t i = 0; i < probs.size(); ++i) probs[i] = std::exp(exact[i]);
  FrameVolume p{probs.data(), VolumeType::float32, VolumeValues::prob, H, W, N, 0.5};
  const auto from_prob = prepare_frame(p, 16), from_log = prepare_frame(a, 16);
  for (std::size_t i = 0; i < probs.size(); ++i) EXPECT_NEAR(from_prob.log_prob[i], from_log.log_prob[i], 1e-5);
  EXPECT_EQ(half_to_float(0x7C00), std::numeric_limits<float>::infinity());
  EXPECT_EQ(half_to_float(0x0001), std::ldexp(1.0f, -24));
}

INSTANTIATE_TEST_SUITE_P(Shapes, Float16Intake,
                         ::testing::Values(std::array<int, 3>{5, 6, 8}, std::array<int, 3>{3, 16, 16}));

// prepare_frame against a plain double-precision log-softmax of the same values raised to the same
// power, on shapes whose widths and bin counts are and are not whole blocks of the vectorized
// transposition, with zero cells and many cells tied at the largest value: every log-probability
// within 1e-6 of the reference relatively, the entropy within 1e-6, the argmax the first largest
// cell in heading-major order, and the same frame, bit for bit, for any number of threads.
TEST(Intake, MatchesADoublePrecisionLogSoftmaxForAnyNumberOfThreads) {
  struct Shape {
    int h, w, n;
    float rise = 0;  ///< nats every value gains from one row to the next
  };
  std::mt19937 rng(21);
  std::normal_distribution<float> noise(0, 3);
  // Rows rising by 20 nats take exps far above 1 against the rows before; rising by 45 (more
  // than the SIMD loops' headroom) or falling, each row's maximum comes and goes. (The rows are
  // centred on 0: values of hundreds of nats would leave float's precision behind.)
  for (const Shape shape : {Shape{16, 32, 16}, Shape{9, 21, 12}, Shape{7, 13, 4}, Shape{4, 16, 24, 20},
                            Shape{3, 16, 8, 45}, Shape{4, 17, 12, -30}}) {
    const std::size_t cells = static_cast<std::size_t>(shape.h) * shape.w * shape.n;
    const std::size_t row = static_cast<std::size_t>(shape.w) * shape.n;
    std::vector<float> values(cells);
    for (std::size_t i = 0; i < cells; ++i) {
      const float offset = shape.rise * (static_cast<float>(i / row) - static_cast<float>(shape.h - 1) / 2);
      values[i] = std::min(4.0f, noise(rng)) + offset;  // clipped: many cells tie at each row's top
    }
    for (std::size_t i = 5; i < cells; i += 17) values[i] = -std::numeric_limits<float>::infinity();
    for (const double power : {1.0, 0.3, 2.5}) {
      const FrameVolume volume{
          values.data(), VolumeType::float32, VolumeValues::log_prob, shape.h, shape.w, shape.n, 0.5};
      const PreparedFrame f = prepare_frame(volume, shape.n, 1, power);
      // The reference: heading-major, in double.
      const std::size_t slice = static_cast<std::size_t>(shape.h) * shape.w;
      std::vector<double> x(cells);
      double max = -std::numeric_limits<double>::infinity();
      for (int v = 0; v < shape.h; ++v)
        for (int u = 0; u < shape.w; ++u)
          for (int j = 0; j < shape.n; ++j) {
            const float given = values[(static_cast<std::size_t>(v) * shape.w + u) * shape.n + j];
            const double raised = std::isinf(given) ? -std::numeric_limits<double>::infinity()
                                                    : static_cast<double>(static_cast<float>(given * power));
            x[static_cast<std::size_t>(j) * slice + static_cast<std::size_t>(v) * shape.w + u] = raised;
            max = std::max(max, raised);
          }
      double sum = 0, ex = 0;
      for (const double y : x) {
        if (std::isinf(y)) continue;
        sum += std::exp(y - max);
        ex += std::exp(y - max) * y;
      }
      const double lse = max + std::log(sum);
      EXPECT_NEAR(f.entropy, (lse - ex / sum) / std::log(static_cast<double>(cells)), 1e-6)
          << shape.h << "x" << shape.w << "x" << shape.n << " rising " << shape.rise << " power " << power;
      const std::size_t first =
          static_cast<std::size_t>(std::max_element(x.begin(), x.end()) - x.begin());  // the first largest
      EXPECT_EQ(f.argmax_bin, static_cast<int>(first / slice)) << power;
      EXPECT_EQ(f.argmax_v * shape.w + f.argmax_u, static_cast<int>(first % slice)) << power;
      for (std::size_t i = 0; i < cells; ++i) {
        if (std::isinf(x[i])) {
          ASSERT_EQ(f.log_prob[i], kLogZero) << i;
        } else {
          ASSERT_NEAR(f.log_prob[i], x[i] - lse, 1e-6 * std::max(1.0, std::abs(x[i] - lse))) << i << " power " << power;
        }
      }
      EXPECT_EQ(f.max_log_prob, f.log_prob[first]);
      for (const int threads : {2, 3, 5}) {
        const PreparedFrame g = prepare_frame(volume, shape.n, threads, power);
        EXPECT_EQ(g.log_prob, f.log_prob) << threads << " threads";
        EXPECT_EQ(g.entropy, f.entropy);
        EXPECT_EQ(g.argmax_bin, f.argmax_bin);
        EXPECT_EQ(g.argmax_v, f.argmax_v);
        EXPECT_EQ(g.argmax_u, f.argmax_u);
      }
    }
  }
}

// prepare_frame's loops at each vector width this CPU runs (16: AVX-512, 8: AVX2, 1: portable):
// 16 and 8 give the same frame bit for bit (the same operations lane by lane), the portable loops
// the same within 1e-6; float16 and float32, odd shapes whose bins leave a partial vector, rows
// far above the ones before them, and a power.
TEST(Intake, EveryVectorWidthGivesTheSameFrame) {
  const int widest = intake_vector_lanes();
  struct Restore {
    ~Restore() { (void)limit_intake_vector_lanes(16); }
  } restore;
  std::mt19937 rng(33);
  std::normal_distribution<float> noise(-6, 3);
  for (const auto& [h, w, n] : {std::array<int, 3>{8, 32, 64}, std::array<int, 3>{5, 19, 24}}) {
    const std::size_t cells = static_cast<std::size_t>(h) * w * n;
    std::vector<float> floats(cells);
    for (std::size_t i = 0; i < cells; ++i) {
      floats[i] = std::round((noise(rng) + (i / (static_cast<std::size_t>(w) * n) == 3 ? 50.0f : 0.0f)) * 64) / 64;
    }
    for (std::size_t i = 2; i < cells; i += 13) floats[i] = -std::numeric_limits<float>::infinity();
    const std::vector<std::uint16_t> halves = halves_of(floats);
    for (const bool half : {false, true}) {
      const FrameVolume volume = log_prob_view(floats, halves, half, h, w, n);
      for (const double power : {1.0, 0.6}) {
        std::vector<PreparedFrame> frames;
        for (const int lanes : {16, 8, 1}) {
          (void)limit_intake_vector_lanes(lanes);
          ASSERT_EQ(intake_vector_lanes(), std::min(lanes, widest));
          frames.push_back(prepare_frame(volume, n, 2, power));
        }
        EXPECT_EQ(frames[0].log_prob, frames[1].log_prob) << h << "x" << w << "x" << n << " half " << half;
        EXPECT_EQ(frames[0].entropy, frames[1].entropy);
        for (std::size_t i = 0; i < cells; ++i) {
          ASSERT_NEAR(frames[2].log_prob[i], frames[1].log_prob[i],
                      1e-6 * std::max(1.0f, std::abs(frames[1].log_prob[i])))
              << i << " half " << half << " power " << power;
        }
        EXPECT_NEAR(frames[2].entropy, frames[1].entropy, 1e-6);
        for (const auto& f : frames) {
          EXPECT_EQ(f.argmax_bin * h * w + f.argmax_v * w + f.argmax_u,
                    frames[1].argmax_bin * h * w + frames[1].argmax_v * w + frames[1].argmax_u);
        }
      }
    }
  }
  EXPECT_THROW((void)limit_intake_vector_lanes(4), IntakeError);
}

// The power given to prepare_frame is temper_frame's: p^k / sum p^k.
TEST(Intake, APowerGivenToPrepareFrameIsTemperFramesPower) {
  std::mt19937 rng(4);
  const Volume vol = random_volume(rng, 9, 11, 16);
  for (const double power : {0.25, 3.0}) {
    const PreparedFrame at_once = prepare_frame(vol.view(9, 11, 16), 16, 1, power);
    const PreparedFrame after = temper_frame(prepare_frame(vol.view(9, 11, 16), 16), power);
    ASSERT_EQ(at_once.log_prob.size(), after.log_prob.size());
    for (std::size_t i = 0; i < after.log_prob.size(); ++i) {
      ASSERT_NEAR(at_once.log_prob[i], after.log_prob[i], 1e-5 * std::max(1.0f, std::abs(after.log_prob[i]))) << i;
    }
    EXPECT_NEAR(at_once.entropy, after.entropy, 1e-6);
    EXPECT_EQ(at_once.argmax_bin * 99 + at_once.argmax_v * 11 + at_once.argmax_u,
              after.argmax_bin * 99 + after.argmax_v * 11 + after.argmax_u);
  }
  EXPECT_THROW((void)prepare_frame(vol.view(9, 11, 16), 16, 1, 0.0), IntakeError);
  EXPECT_THROW((void)prepare_frame(vol.view(9, 11, 16), 16, 1, std::nan("")), IntakeError);
}

}  // namespace
}  // namespace seqloc::intake
