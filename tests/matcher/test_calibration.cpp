// Calibration of likelihood volumes: calibrate_volume against direct computations (log-softmax,
// a blurred delta, the floor), and the fit recovering the temperature that generated the truths.

#include <array>
#include <cmath>
#include <cstring>
#include <numeric>
#include <random>

#include <gtest/gtest.h>

#include "seqloc/core/error.hpp"
#include "seqloc/matcher/calibration.hpp"

namespace seqloc::matcher {
namespace {

std::size_t at(int v, int u, int b, int width, int bins) {
  return (static_cast<std::size_t>(v) * static_cast<std::size_t>(width) + static_cast<std::size_t>(u)) *
             static_cast<std::size_t>(bins) +
         static_cast<std::size_t>(b);
}

TEST(CalibrateVolume, IdentityIsALogSoftmax) {
  std::mt19937 rng(1);
  std::normal_distribution<float> d(0.0F, 5.0F);
  std::vector<float> volume(7 * 5 * 4);
  for (auto& v : volume) v = d(rng) + 100.0F;  // any offset
  auto calibrated = volume;
  matcher::calibrate_volume(calibrated, 7, 5, 4, {});
  double z = 0;
  for (float v : volume) z += std::exp(static_cast<double>(v) - 100.0);
  for (std::size_t i = 0; i < volume.size(); ++i) {
    EXPECT_NEAR(calibrated[i], static_cast<double>(volume[i]) - 100.0 - std::log(z), 1e-5);
  }
}

// The heading-major calibration (a prepared frame's layout) against calibrate_volume of the same
// volume turned to (H, W, N): the same values to float rounding for each kind of calibration, on a
// shape whose sides differ, and the same bits for any number of threads.
TEST(CalibrateVolume, HeadingMajorEqualsTheVolumeLayout) {
  const int H = 9, W = 13, N = 12;
  std::mt19937 rng(5);
  std::normal_distribution<float> d(0.0F, 4.0F);
  std::vector<float> hwn(static_cast<std::size_t>(H) * W * N);
  for (auto& v : hwn) v = d(rng);
  const std::size_t slice = static_cast<std::size_t>(H) * W;
  auto heading_major = [&](const std::vector<float>& from) {
    std::vector<float> out(from.size());
    for (int v = 0; v < H; ++v)
      for (int u = 0; u < W; ++u)
        for (int b = 0; b < N; ++b)
          out[static_cast<std::size_t>(b) * slice + static_cast<std::size_t>(v) * W + u] = from[at(v, u, b, W, N)];
    return out;
  };
  for (const VolumeCalibration c : {VolumeCalibration{1.5, 0, 0}, VolumeCalibration{0, 2.0, 0},
                                    VolumeCalibration{0, 0, 0.3}, VolumeCalibration{2.5, 1.0, 0.05},
                                    VolumeCalibration{}}) {
    auto expected = hwn;
    calibrate_volume(expected, H, W, N, c);
    const auto want = heading_major(expected);
    auto got = heading_major(hwn);
    calibrate_heading_major(got, N, H, W, c);
    for (std::size_t i = 0; i < got.size(); ++i) {
      ASSERT_NEAR(got[i], want[i], 1e-6 * std::max(1.0f, std::abs(want[i])))
          << i << " blur " << c.blur_cells << " / " << c.blur_bins << " floor " << c.floor;
    }
    auto threaded = heading_major(hwn);
    calibrate_heading_major(threaded, N, H, W, c, 3);
    EXPECT_EQ(threaded, got);
  }
  std::vector<float> wrong(10);
  EXPECT_THROW(calibrate_heading_major(wrong, N, H, W, {}), UsageError);
}

TEST(CalibrateVolume, TheSameBitsForAnyNumberOfThreads) {
  // Every stage works on separate cells (the blocks of exp and log, the heading blur per cell, the
  // row and column blurs): however the shared pool splits them, each value is computed alike.
  const int H = 37, W = 29, N = 12;
  std::mt19937 rng(3);
  std::normal_distribution<float> d(0.0F, 4.0F);
  std::vector<float> volume(static_cast<std::size_t>(H * W * N));
  for (auto& v : volume) v = d(rng);
  const matcher::VolumeCalibration c{2.0, 1.5, 0.05};
  auto one = volume;
  matcher::calibrate_volume(one, H, W, N, c, 1);
  for (const int threads : {2, 3, 7}) {
    auto many = volume;
    matcher::calibrate_volume(many, H, W, N, c, threads);
    ASSERT_EQ(std::memcmp(one.data(), many.data(), one.size() * sizeof(float)), 0) << threads << " threads";
  }
}

TEST(CalibrateVolume, ADeltaBecomesTheProductOfGaussiansPlusTheFloor) {
  const int H = 31, W = 31, N = 16;
  std::vector<float> volume(static_cast<std::size_t>(H * W * N), -1e30F);
  volume[at(15, 15, 1, W, N)] = 0;
  const matcher::VolumeCalibration c{2.0, 1.5, 0.05};
  matcher::calibrate_volume(volume, H, W, N, c);
  const auto gxy = matcher::gaussian_taps(2.0), gb = matcher::gaussian_taps(1.5);
  ASSERT_EQ(gxy.size(), 13u);  // 3 sigma = 6 cells each side
  ASSERT_EQ(gb.size(), 11u);
  const double uniform = 0.05 / (H * W * N);
  double total = 0;
  for (int v = 0; v < H; ++v) {
    for (int u = 0; u < W; ++u) {
      for (int b = 0; b < N; ++b) {
        const double p = std::exp(static_cast<double>(volume[at(v, u, b, W, N)]));
        total += p;
        double expected = 0;
        if (std::abs(v - 15) <= 6 && std::abs(u - 15) <= 6) {
          // Heading: circular, bin 1 -> bins 1 - 5 .. 1 + 5 wrap to 12..15, 0..6.
          for (int j = -5; j <= 5; ++j) {
            if ((((1 + j) % N) + N) % N == b) expected += gb[static_cast<std::size_t>(j + 5)];
          }
          expected *= gxy[static_cast<std::size_t>(v - 15 + 6)] * gxy[static_cast<std::size_t>(u - 15 + 6)];
        }
        EXPECT_NEAR(p, 0.95 * expected + uniform, 1e-6) << v << "," << u << "," << b;
      }
    }
  }
  EXPECT_NEAR(total, 1.0, 1e-6);
}

// Volumes of random scores whose true cells are drawn from softmax(s / 4): the fit must find 4,
// and its NLL must equal calibrate_volume's own value at the true cells.
TEST(CalibrationFit, RecoversTheTemperatureThatDrewTheTruths) {
  const int H = 9, W = 9, N = 8;
  matcher::CalibrationFit::Grid grid;
  grid.temperatures = {2, 3, 4, 5, 6, 8};
  grid.blur_cells = {0, 1};
  grid.blur_bins = {0, 1};
  grid.floors = {0, 0.01, 0.1};
  matcher::CalibrationFit fit(grid);
  std::mt19937 rng(3);
  std::normal_distribution<float> d(0.0F, 8.0F);
  std::vector<std::vector<float>> kept;
  std::vector<std::array<int, 3>> truths;
  for (int f = 0; f < 3000; ++f) {
    std::vector<float> s(static_cast<std::size_t>(H * W * N));
    for (auto& v : s) v = d(rng);
    std::vector<double> p(s.size());
    for (std::size_t i = 0; i < s.size(); ++i) p[i] = std::exp(s[i] / 4.0);
    const auto cell = static_cast<int>(std::discrete_distribution<std::size_t>(p.begin(), p.end())(rng));
    const int b = cell % N, u = (cell / N) % W, v = cell / (N * W);
    fit.add(s, H, W, N, v, u, b);
    if (f < 200) {
      kept.push_back(s);
      truths.push_back({v, u, b});
    }
  }
  fit.add(std::vector<float>(static_cast<std::size_t>(H * W * N), 0.0F), H, W, N, 9, 0, 0);  // outside: skipped
  const auto best = fit.best();
  EXPECT_EQ(best.temperature, 4);
  EXPECT_EQ(best.calibration.blur_cells, 0);
  EXPECT_EQ(best.calibration.blur_bins, 0);
  EXPECT_EQ(best.frames, 3000u);
  EXPECT_EQ(best.skipped, 1u);
  EXPECT_NEAR(best.uniform_nll, std::log(H * W * N), 1e-12);
  EXPECT_LT(best.nll, fit.mean_nll(3, {}));
  EXPECT_LT(best.nll, fit.mean_nll(5, {}));

  // The fit's NLL of a setting without positional blur (so no mass leaves the crop) is exactly
  // that of the calibrated volumes at the true cells, here over a fit of the first 200 frames.
  matcher::CalibrationFit small(grid);
  double direct = 0;
  const matcher::VolumeCalibration c{0, 1, 0.1};
  for (std::size_t f = 0; f < kept.size(); ++f) {
    small.add(kept[f], H, W, N, truths[f][0], truths[f][1], truths[f][2]);
    std::vector<float> scaled(kept[f].size());
    for (std::size_t i = 0; i < scaled.size(); ++i) scaled[i] = kept[f][i] / 6.0F;
    matcher::calibrate_volume(scaled, H, W, N, c);
    direct -= scaled[at(truths[f][0], truths[f][1], truths[f][2], W, N)];
  }
  EXPECT_NEAR(small.mean_nll(6, c), direct / static_cast<double>(kept.size()), 1e-5);
}

TEST(CalibrateVolume, ThreadsGiveTheSameBits) {
  std::mt19937 rng(9);
  std::normal_distribution<float> d(0.0F, 6.0F);
  std::vector<float> volume(static_cast<std::size_t>(23 * 17 * 12));
  for (auto& v : volume) v = d(rng);
  auto one = volume, three = volume;
  matcher::calibrate_volume(one, 23, 17, 12, {2.0, 1.5, 0.3}, 1);
  matcher::calibrate_volume(three, 23, 17, 12, {2.0, 1.5, 0.3}, 3);
  EXPECT_EQ(one, three);
}

TEST(CalibrateVolume, RefusesBadSettingsAndSizes) {
  std::vector<float> v(8, 0.0F);
  EXPECT_THROW(matcher::calibrate_volume(v, 2, 2, 2, {0, 0, 1.0}), UsageError);
  EXPECT_THROW(matcher::calibrate_volume(v, 2, 2, 2, {-1, 0, 0}), UsageError);
  EXPECT_THROW(matcher::calibrate_volume(v, 3, 2, 2, {}), UsageError);
}

}  // namespace
}  // namespace seqloc::matcher
