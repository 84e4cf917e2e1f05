// A pose's uncertainty from its belief, on beliefs whose answer is known analytically: a Gaussian
// of given covariance, two separated modes, a heading spread, and the 95 % ellipse against
// samples of the Gaussian it describes.

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "seqloc/filter/belief.hpp"
#include "seqloc/uncertainty/pose_uncertainty.hpp"

namespace seqloc::uncertainty {

using filter::BeliefVolume;
namespace {

constexpr double kCell = 0.5;
constexpr double kQuantization = kCell * kCell / 12;  // a cell's own variance (pose_uncertainty.hpp)

// Adds `weight` times a Gaussian in position (east/north sigmas in m, correlation rho) centred
// at window cell (u0, v0), uniform in heading, to `b`.
void add_gaussian(BeliefVolume& b, double u0, double v0, double sigma_e, double sigma_n, double rho, double weight) {
  const double det = sigma_e * sigma_e * sigma_n * sigma_n * (1 - rho * rho);
  const double inv_ee = sigma_n * sigma_n / det, inv_nn = sigma_e * sigma_e / det;
  const double inv_en = -rho * sigma_e * sigma_n / det;
  std::vector<double> g(b.slice_cells());
  double sum = 0;
  for (int v = 0; v < b.height(); ++v)
    for (int u = 0; u < b.width(); ++u) {
      const double e = (u - u0) * kCell, n = -(v - v0) * kCell;
      const double x = std::exp(-0.5 * (inv_ee * e * e + 2 * inv_en * e * n + inv_nn * n * n));
      g[static_cast<std::size_t>(v) * b.width() + u] = x;
      sum += x;
    }
  for (int k = 0; k < b.headings(); ++k)
    for (std::size_t i = 0; i < b.slice_cells(); ++i)
      b.slice(k)[i] += static_cast<float>(weight * g[i] / sum / b.headings());
}

BeliefVolume empty(int w, int h, int r) {
  BeliefVolume b(w, h, r);
  std::fill(b.data(), b.data() + b.size(), 0.0f);
  return b;
}

TEST(Uncertainty, AGaussianGivesItsCovarianceAboutItsMean) {
  BeliefVolume b = empty(160, 160, 8);
  const double se = 4, sn = 2, rho = 0.5;
  add_gaussian(b, 80, 80, se, sn, rho, 1.0);
  const PoseUncertainty at_mean = pose_uncertainty(b, {80, 80, 0}, 2);
  EXPECT_NEAR(at_mean.cov_ee_m2, se * se + kQuantization, 0.01 * se * se);
  EXPECT_NEAR(at_mean.cov_nn_m2, sn * sn + kQuantization, 0.01 * sn * sn);
  EXPECT_NEAR(at_mean.cov_en_m2, rho * se * sn, 0.01 * se * sn);
  EXPECT_FALSE(at_mean.multimodal);
  // Within 5 m: the Gaussian's probability of the disc, by sampling it (sd 0.1 %; cells counted
  // by their centres add about as much).
  std::mt19937 rng(11);
  std::normal_distribution<double> z(0, 1);
  int near = 0;
  const int samples = 200000;
  for (int i = 0; i < samples; ++i) {
    const double z1 = z(rng), z2 = z(rng);
    const double e = se * z1, n = sn * (rho * z1 + std::sqrt(1 - rho * rho) * z2);
    near += e * e + n * n <= 25 ? 1 : 0;
  }
  EXPECT_NEAR(at_mean.mass_within_5m, static_cast<double>(near) / samples, 0.01);

  // About an estimate 2 m east of the mean, the east variance grows by 2^2 and nothing else moves.
  const PoseUncertainty off = pose_uncertainty(b, {84, 80, 0}, 1);
  EXPECT_NEAR(off.cov_ee_m2, at_mean.cov_ee_m2 + 4, 1e-6);
  EXPECT_NEAR(off.cov_en_m2, at_mean.cov_en_m2, 1e-6);
  EXPECT_NEAR(off.cov_nn_m2, at_mean.cov_nn_m2, 1e-6);
}

TEST(Uncertainty, TwoPlacesFortyMetresApartAreFlaggedAndTheCovarianceSpansThem) {
  BeliefVolume b = empty(200, 80, 4);
  add_gaussian(b, 40, 40, 1, 1, 0, 0.7);
  add_gaussian(b, 120, 40, 1, 1, 0, 0.3);  // 80 cells = 40 m east
  const PoseUncertainty u = pose_uncertainty(b, {40, 40, 0});
  EXPECT_TRUE(u.multimodal);
  EXPECT_NEAR(u.second_mode_share, 0.3, 0.005);
  EXPECT_NEAR(u.second_mode_distance_m, 40, 0.01);
  EXPECT_NEAR(u.mass_within_5m, 0.7, 0.005);
  // E[(x - A)^2] east: 0.7 sigma^2 + 0.3 (40^2 + sigma^2).
  EXPECT_NEAR(u.cov_ee_m2, 0.7 * 1 + 0.3 * (1600 + 1) + kQuantization, 0.01 * 480);
  EXPECT_NEAR(u.cov_nn_m2, 1 + kQuantization, 0.02);

  // A second place under the stated share is not a second mode.
  BeliefVolume c = empty(200, 80, 4);
  add_gaussian(c, 40, 40, 1, 1, 0, 0.95);
  add_gaussian(c, 120, 40, 1, 1, 0, 0.05);
  const PoseUncertainty one = pose_uncertainty(c, {40, 40, 0});
  EXPECT_FALSE(one.multimodal);
  EXPECT_NEAR(one.second_mode_share, 0.05, 0.005);
}

TEST(Uncertainty, ARidgeAlongARoadIsOnePlaceNotTwo) {
  // A long ridge (sigma 20 m along, 1 m across, turned 30 degrees from east): its far cells hold
  // much of the mass within 5 m of them, but no valley parts them from the estimate.
  BeliefVolume b = empty(240, 240, 4);
  const double c = std::cos(30 * M_PI / 180), s = std::sin(30 * M_PI / 180);
  const double se = std::sqrt(400 * c * c + 1 * s * s), sn = std::sqrt(400 * s * s + 1 * c * c);
  const double rho = (400 - 1) * c * s / (se * sn);
  add_gaussian(b, 120, 120, se, sn, rho, 1.0);
  const PoseUncertainty u = pose_uncertainty(b, {120, 120, 0});
  EXPECT_FALSE(u.multimodal);
  EXPECT_EQ(u.second_mode_share, 0.0);
  // The covariance says how long the ridge is instead: 400 m^2 along it.
  const Ellipse e = covariance_ellipse(u.cov_ee_m2, u.cov_en_m2, u.cov_nn_m2, 0.95);
  EXPECT_NEAR(e.major_m, std::sqrt(5.991465 * (400 + kQuantization)), 0.03 * e.major_m);
  EXPECT_NEAR(e.major_bearing_deg, 60, 0.5);  // 30 degrees north of east
}

TEST(Uncertainty, HeadingSpreadIsTheWrappedSdAboutTheEstimate) {
  BeliefVolume b = empty(16, 16, 72);  // 5 degree bins
  const double sd = 10;
  double sum = 0;
  for (int k = 0; k < 72; ++k) {
    const double d = std::remainder(k * 5.0 - 355.0, 360.0);  // centred on 355: wraps past north
    sum += std::exp(-0.5 * d * d / (sd * sd));
  }
  for (int k = 0; k < 72; ++k) {
    const double d = std::remainder(k * 5.0 - 355.0, 360.0);
    const auto x = static_cast<float>(std::exp(-0.5 * d * d / (sd * sd)) / sum / static_cast<double>(b.slice_cells()));
    std::fill(b.slice(k), b.slice(k) + b.slice_cells(), x);
  }
  const PoseUncertainty u = pose_uncertainty(b, {8, 8, 355});
  EXPECT_NEAR(u.heading_sd_deg, std::sqrt(sd * sd + 25.0 / 12), 0.05);
  const PoseUncertainty off = pose_uncertainty(b, {8, 8, 5});  // 10 degrees off, across north
  EXPECT_NEAR(off.heading_sd_deg, std::sqrt(sd * sd + 100 + 25.0 / 12), 0.05);
}

TEST(Uncertainty, TheNinetyFivePercentEllipseHoldsNinetyFivePercentOfItsGaussian) {
  const Ellipse axis = covariance_ellipse(4, 0, 1, 0.95);
  EXPECT_NEAR(axis.major_m, std::sqrt(5.991465 * 4), 1e-4);
  EXPECT_NEAR(axis.minor_m, std::sqrt(5.991465 * 1), 1e-4);
  EXPECT_NEAR(axis.major_bearing_deg, 90, 1e-9);  // east
  EXPECT_NEAR(covariance_ellipse(2, 1, 2, 0.95).major_bearing_deg, 45, 1e-9);
  EXPECT_NEAR(covariance_ellipse(1, 0, 4, 0.95).major_bearing_deg, 0, 1e-9);  // north
  EXPECT_TRUE(inside_ellipse(4, 0, 1, 4.8, 0, 0.95));
  EXPECT_FALSE(inside_ellipse(4, 0, 1, 5.0, 0, 0.95));

  // Samples of N(0, [[9, 3], [3, 4]]): the share inside is 95 % to within sampling (sd 0.15 %).
  std::mt19937 rng(7);
  std::normal_distribution<double> z(0, 1);
  const double a = 3, b = 1, c = std::sqrt(4 - 1);  // Cholesky: e = 3 z1, n = z1 + sqrt(3) z2
  int inside = 0;
  const int n = 20000;
  for (int i = 0; i < n; ++i) {
    const double z1 = z(rng), z2 = z(rng);
    inside += inside_ellipse(9, 3, 4, a * z1, b * z1 + c * z2, 0.95) ? 1 : 0;
  }
  EXPECT_NEAR(static_cast<double>(inside) / n, 0.95, 0.006);
}

}  // namespace
}  // namespace seqloc::uncertainty
