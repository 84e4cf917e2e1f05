// DepthHistogram (selfcal/estimator.hpp): the fixed-point bins self-calibration's sums are read
// from. Its SIMD add_each, its merge and its reuse after clear() must give exactly the sums that
// one add() per cell into a new histogram gives.

#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "seqloc/selfcal/estimator.hpp"

namespace seqloc::selfcal {
namespace {

const std::vector<double> kPowers = {0.0625, 0.5, 1.0, 3.0, 16.0};

// Cells at depths in [-from, -to] nats with masses from 1e-12 to 0.1 (a tenth of them zero where
// `zeros`).
void cells(unsigned seed, double from, double to, std::vector<float>& r, std::vector<float>& w, bool zeros = true) {
  std::mt19937 rng(seed);
  std::uniform_real_distribution<double> depth(to, from), log_mass(-12, -1), unit(0, 1);
  r.resize(5000);
  w.resize(r.size());
  for (std::size_t i = 0; i < r.size(); ++i) {
    r[i] = static_cast<float>(-depth(rng));
    w[i] = zeros && unit(rng) < 0.1 ? 0.0f : static_cast<float>(std::pow(10.0, log_mass(rng)));
  }
}

DepthHistogram one_by_one(const std::vector<float>& r, const std::vector<float>& w) {
  DepthHistogram h;
  for (std::size_t i = 0; i < r.size(); ++i) {
    if (w[i] > 0) h.add(r[i], w[i]);
  }
  return h;
}

void expect_same(const DepthHistogram& a, const DepthHistogram& b) {
  EXPECT_EQ(a.total(), b.total());
  const auto la = a.log_sum_exp(kPowers), lb = b.log_sum_exp(kPowers);
  for (std::size_t k = 0; k < kPowers.size(); ++k) EXPECT_EQ(la[k], lb[k]) << "power " << kPowers[k];
}

TEST(DepthHistogram, AddEachIsAddForEveryCell) {
  std::vector<float> r, w;
  cells(1, 250, 0, r, w);  // past the deepest bin too
  DepthHistogram h;
  h.add_each(r, w);
  expect_same(h, one_by_one(r, w));
  EXPECT_GT(h.total(), 0);
}

// A histogram cleared and filled again is a new histogram of what it was filled with again, over
// the same depths and over shallower ones; two histograms over disjoint depths merge into the
// histogram of both.
TEST(DepthHistogram, ClearAndMergeKeepTheSumsOfANewHistogram) {
  std::vector<float> deep_r, deep_w, again_r, again_w, shallow_r, shallow_w;
  cells(2, 180, 120, deep_r, deep_w, false);
  cells(4, 180, 120, again_r, again_w, false);
  cells(3, 8, 0, shallow_r, shallow_w);
  DepthHistogram reused;
  reused.add_each(deep_r, deep_w);
  reused.clear();
  EXPECT_EQ(reused.total(), 0);
  reused.add_each(again_r, again_w);
  expect_same(reused, one_by_one(again_r, again_w));
  reused.clear();
  reused.add_each(shallow_r, shallow_w);
  expect_same(reused, one_by_one(shallow_r, shallow_w));

  DepthHistogram deep, both;
  deep.add_each(deep_r, deep_w);
  both.merge(reused);
  both.merge(deep);
  std::vector<float> all_r = shallow_r, all_w = shallow_w;
  all_r.insert(all_r.end(), deep_r.begin(), deep_r.end());
  all_w.insert(all_w.end(), deep_w.begin(), deep_w.end());
  expect_same(both, one_by_one(all_r, all_w));
}

}  // namespace
}  // namespace seqloc::selfcal
