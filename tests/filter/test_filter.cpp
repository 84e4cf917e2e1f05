// The SeqLoc filter: the fast implementation against the double-precision reference on seeded
// random inputs, the analytic cases of conventions.md section 6, and robust intake.

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <random>
#include <span>
#include <string>
#include <utility>
#include <vector>

#include <gtest/gtest.h>

#include "filter/reference_filter.hpp"
#include "seqloc/filter/seqloc_filter.hpp"
#include "support/volumes.hpp"

namespace seqloc::filter {
namespace {

using test::ReferenceFilter;

FilterConfig small_config() {
  FilterConfig c;
  c.width = 24;
  c.height = 20;
  c.headings = 16;
  return c;
}

using seqloc::test::random_volume;
using seqloc::test::Volume;

// The fast filter keeps float probabilities, the reference double log-probabilities. Each
// probability goes through a few dozen float operations per step (relative rounding 6e-8 each),
// five steps deep: 2e-4 relative is over two orders of magnitude above that drift and far below
// what a wrong index or weight does (>= 1e-2 on these inputs). Below 1e-12 (mass that no
// decision can see) float may also round to zero, hence the absolute floor.
void expect_same_belief(const BeliefVolume& fast, const ReferenceFilter& ref, const std::string& what) {
  for (int k = 0; k < fast.headings(); ++k)
    for (int v = 0; v < fast.height(); ++v)
      for (int u = 0; u < fast.width(); ++u) {
        const double r = std::exp(ref.at(u, v, k));
        const double diff = std::abs(fast.prob(u, v, k) - r);
        ASSERT_LE(diff, 2e-4 * r + 1e-12) << what << " at (" << u << ", " << v << ", " << k << "): fast "
                                          << fast.prob(u, v, k) << ", reference " << r;
      }
}

struct Variant {
  const char* name;
  bool etu, mgr, pas;
  double rotation_deg;
  double cell_m;
  int bins;
  int threads;
  double outside_nats = 1.0;
  double etu_reference = 0.9;
  bool self_calibrate = true;
};

// Printed by name: without it GoogleTest dumps the struct's bytes, padding included, which
// Valgrind rightly reports as reads of uninitialised memory.
void PrintTo(const Variant& v, std::ostream* os) { *os << v.name; }

class FastAgainstReference : public ::testing::TestWithParam<Variant> {};

TEST_P(FastAgainstReference, AgreeOnSeededRandomSequences) {
  const Variant& p = GetParam();
  FilterConfig c = small_config();
  c.etu = p.etu;
  c.mgr = p.mgr;
  c.pas = p.pas;
  c.threads = p.threads;
  c.outside_crop_nats = p.outside_nats;
  c.etu_reference_entropy = p.etu_reference;
  c.self_calibrate = p.self_calibrate;
  c.self_calibration_hold_share = 0;  // no hold: the estimate's power on every frame, the path to check
  // Nor the shared errors' factor: its moves raise the belief (StepDecisions::belief_ratio), a
  // decision the reference does not make (checked in StepDecisions.* and EarlyReplay.*).
  c.self_calibration_shared_lag = 0;
  std::mt19937 rng(1234);
  std::uniform_real_distribution<double> unit(0, 1);
  std::vector<float> road(static_cast<std::size_t>(c.width * c.height));
  for (auto& d : road) d = static_cast<float>(30 * unit(rng) * unit(rng));
  SeqLocFilter fast(c);
  ReferenceFilter ref(c);
  bool tempered = false;  // self-calibration raised some frame to a power other than 1
  for (int step = 0; step < 5; ++step) {
    const int h = 9 + step % 3, w = 11 - step % 2;
    const Volume vol = random_volume(rng, h, w, p.bins);
    const FrameVolume view = vol.view(h, w, p.bins, p.cell_m);
    const CropPose crop{6 + 12 * unit(rng), 5 + 10 * unit(rng), p.rotation_deg == 0 ? 0.0 : p.rotation_deg + 10 * step};
    const Odometry odo{3 * unit(rng), unit(rng) - 0.5, 40 * unit(rng) - 20};
    const auto a = fast.step(prepare_frame(view, c.headings), crop, odo, road);
    const auto b = ref.step(view, crop, odo, road, std::nullopt, a.volume_power);
    expect_same_belief(fast.belief(), ref, std::string(p.name) + " step " + std::to_string(step));
    EXPECT_EQ(a.argmax.u, b.argmax.u);
    EXPECT_EQ(a.argmax.v, b.argmax.v);
    EXPECT_EQ(a.argmax.heading_deg, b.argmax.heading_deg);
    EXPECT_NEAR(a.pose.u, b.pose.u, 1e-3);
    EXPECT_NEAR(a.pose.v, b.pose.v, 1e-3);
    // A tempered frame's float log-probabilities are rounded once more (|log p| up to ~30 nats here,
    // times 6e-8: 2e-6 absolute), which the entropy carries and ETU's weight multiplies by
    // 1 / (1 - H_ref) = 10; an untempered frame keeps the tighter bound.
    const double entropy_tolerance = a.volume_power == 1.0 ? 1e-6 : 5e-6;
    EXPECT_NEAR(a.frame_entropy, b.frame_entropy, entropy_tolerance);
    EXPECT_NEAR(a.etu_weight, b.etu_weight, entropy_tolerance * 10);
    tempered = tempered || a.volume_power != 1.0;
  }
  EXPECT_EQ(tempered, p.self_calibrate) << "self-calibration must act on these frames exactly when it is on";
}

INSTANTIATE_TEST_SUITE_P(
    Filter, FastAgainstReference,
    ::testing::Values(Variant{"seqloc", true, true, true, 0, 0.5, 16, 1},
                      Variant{"naive", false, false, false, 0, 0.5, 16, 1},
                      Variant{"etu_only", true, false, false, 0, 0.5, 16, 1},
                      Variant{"mgr_only", false, true, false, 0, 0.5, 16, 2},
                      Variant{"rotated_crop", true, true, true, 7.5, 0.5, 16, 1},
                      Variant{"coarse_volume", true, true, true, 0, 1.0, 16, 1},
                      Variant{"fewer_bins", true, true, true, 0, 0.5, 8, 1},
                      Variant{"more_bins", true, true, true, 3.0, 0.5, 32, 2},
                      Variant{"threads", true, true, true, 0, 0.5, 16, 3},
                      Variant{"outside_crop", true, true, true, 7.5, 0.5, 16, 1, 2.0},
                      Variant{"paper_etu", true, true, true, 0, 0.5, 16, 1, 0.0, 0.0},
                      Variant{"no_self_calibration", true, true, true, 7.5, 0.5, 16, 1, 1.0, 0.9, false}),
    [](const auto& variant) { return std::string(variant.param.name); });

// A volume whose mass is one cell: log-prob 0 there, -inf elsewhere.
Volume delta_volume(int h, int w, int n, int v, int u, int j) {
  Volume d;
  d.values.assign(static_cast<std::size_t>(h * w * n), -std::numeric_limits<float>::infinity());
  d.values[static_cast<std::size_t>((v * w + u) * n + j)] = 0;
  return d;
}

TEST(Analytic, TheRoadDistanceWindowMustBeTheWindows) {
  // MGR reads the road distance as W x H: a window of another size is refused, never read past.
  FilterConfig c = small_config();
  c.mgr = true;
  SeqLocFilter filter(c);
  const Volume d = delta_volume(9, 11, 16, 3, 7, 4);
  const auto frame = prepare_frame(d.view(9, 11, 16), c.headings);
  const std::vector<float> short_road(static_cast<std::size_t>(c.width * c.height) - 1, 0.0f);
  const BeliefVolume& belief = std::as_const(filter).belief();
  const std::vector<float> before(belief.data(), belief.data() + belief.size());
  try {
    (void)filter.step(frame, {12, 10, 0}, {}, short_road);
    FAIL() << "a road-distance window one value short was taken";
  } catch (const FilterError& e) {
    EXPECT_EQ(e.category(), ErrorCategory::usage);
    EXPECT_NE(std::string(e.what()).find("road-distance window holds"), std::string::npos) << e.what();
  }
  EXPECT_TRUE(std::equal(before.begin(), before.end(), belief.data())) << "the refused step changed the belief";
  EXPECT_THROW((void)filter.step(frame, {12, 10, 0}, {}, {}), FilterError) << "none at all with MGR on";
}

TEST(Analytic, ASharpLikelihoodGivesItsOwnPose) {
  FilterConfig c = small_config();
  c.mgr = false;
  SeqLocFilter filter(c);
  const Volume d = delta_volume(9, 11, 16, 3, 7, 4);
  const auto frame = prepare_frame(d.view(9, 11, 16), c.headings);
  const CropPose crop{12, 10, 0};
  const auto r = filter.step(frame, crop, {}, {});
  const Pose expected = single_frame_pose(frame, crop);
  EXPECT_EQ(expected.u, 12 + (7 - 5));
  EXPECT_EQ(expected.v, 10 + (3 - 4));
  EXPECT_EQ(expected.heading_deg, 4 * 22.5);
  EXPECT_EQ(r.argmax.u, expected.u);
  EXPECT_EQ(r.argmax.v, expected.v);
  EXPECT_EQ(r.argmax.heading_deg, expected.heading_deg);
  EXPECT_NEAR(r.pose.u, expected.u, 1e-9) << "PAS of a single cell is that cell";
  EXPECT_NEAR(r.etu_weight, 1.0, 1e-9) << "a delta has entropy 0";
}

TEST(Analytic, WholeCellTranslationMovesADeltaExactly) {
  FilterConfig c = small_config();
  SeqLocFilter filter(c);
  BeliefVolume& b = filter.belief();
  std::fill(b.data(), b.data() + b.size(), 0.0f);
  b.prob(10, 10, 0) = 0.5f;  // heading 0: north
  b.prob(10, 10, 4) = 0.5f;  // heading 90: east
  filter.predict({2.0, 0.0, 0.0});  // 2 m = 4 cells forward
  EXPECT_EQ(b.prob(10, 6, 0), 0.5f) << "north: v decreases";
  EXPECT_EQ(b.prob(14, 10, 4), 0.5f) << "east: u increases";
  EXPECT_EQ(b.prob(10, 10, 0), 0.0f);
  filter.predict({0.0, 1.0, 0.0});  // 1 m left = 2 cells
  EXPECT_EQ(b.prob(8, 6, 0), 0.5f) << "left of north is west";
  EXPECT_EQ(b.prob(14, 8, 4), 0.5f) << "left of east is north";
  EXPECT_EQ(b.total_probability(), 1.0);
}

TEST(Analytic, YawShiftsHeadingBinsTheRightWay) {
  FilterConfig c = small_config();
  SeqLocFilter filter(c);
  BeliefVolume& b = filter.belief();
  std::fill(b.data(), b.data() + b.size(), 0.0f);
  b.prob(10, 10, 4) = 1;  // east
  filter.predict({0.0, 0.0, 45.0});  // a left turn of 45 degrees: east becomes north-east
  EXPECT_EQ(b.prob(10, 10, 2), 1.0f);
  filter.predict({0.0, 0.0, -11.25});  // half a bin to the right: the mass splits between two bins
  EXPECT_NEAR(b.prob(10, 10, 2), 0.5, 1e-6);
  EXPECT_NEAR(b.prob(10, 10, 3), 0.5, 1e-6);
  EXPECT_NEAR(b.total_probability(), 1.0, 1e-6);
}

TEST(Analytic, ALoopOfOdometryReturnsTheBelief) {
  FilterConfig c = small_config();
  c.width = c.height = 64;
  SeqLocFilter filter(c);
  BeliefVolume& b = filter.belief();
  // A delta at heading 0; a square of 10 m sides with 90-degree left turns (4 bins exactly).
  std::fill(b.data(), b.data() + b.size(), 0.0f);
  b.prob(40, 40, 0) = 1;
  for (int side = 0; side < 4; ++side) {
    filter.predict({10.0, 0.0, 0.0});
    filter.predict({0.0, 0.0, 90.0});
  }
  EXPECT_EQ(b.prob(40, 40, 0), 1.0f) << "integral moves: exact";
  // An octagon with a smooth belief: sub-cell moves interpolate, so the peak returns within a cell.
  b.set_gaussian(32, 32, 2.0);
  const BeliefVolume before = b;
  for (int side = 0; side < 8; ++side) {
    filter.predict({3.3, 0.0, 45.0});
  }
  int best_u = 0, best_v = 0;
  float best = -1;
  for (int v = 0; v < 64; ++v)
    for (int u = 0; u < 64; ++u)
      if (b.prob(u, v, 0) > best) {
        best = b.prob(u, v, 0);
        best_u = u;
        best_v = v;
      }
  EXPECT_LE(std::hypot(best_u - 32, best_v - 32), 1.0);
  EXPECT_NEAR(b.total_probability(), before.total_probability(), 1e-4) << "mass is kept (none left the window)";
}

TEST(Belief, PositionMarginalIsEachCellsSumOverHeadings) {
  BeliefVolume b(7, 5, 8);
  b.set_gaussian(2.3, 3.1, 1.5);
  b.prob(4, 1, 6) += 0.25f;  // one heading of one cell heavier than the others
  const auto marginal = b.position_marginal();
  ASSERT_EQ(marginal.size(), 35u);
  for (int v = 0; v < 5; ++v) {
    for (int u = 0; u < 7; ++u) {
      double sum = 0;
      for (int k = 0; k < 8; ++k) sum += b.prob(u, v, k);
      EXPECT_NEAR(marginal[static_cast<std::size_t>(v) * 7 + u], sum, 1e-7) << u << "," << v;
    }
  }
}

TEST(Analytic, BeliefSumsToOneAfterEveryStep) {
  FilterConfig c = small_config();
  std::mt19937 rng(5);
  std::vector<float> road(static_cast<std::size_t>(c.width * c.height), 4.0f);
  for (const bool mgr : {false, true}) {
    c.mgr = mgr;
    SeqLocFilter filter(c);
    for (int step = 0; step < 6; ++step) {
      const Volume vol = random_volume(rng, 9, 11, 16);
      filter.step(prepare_frame(vol.view(9, 11, 16), c.headings), {12, 10, 0}, {1.5, 0.2, 7}, road);
      EXPECT_NEAR(filter.belief().total_probability(), 1.0, 1e-3) << "mgr " << mgr << " step " << step;
    }
  }
}

// A frame that says "I am somewhere in this crop" (its volume uniform over the crop) must move
// the belief into the crop: the crop is placed to contain the vehicle. Under the paper's rule
// (outside cells get log(1/M), as much as every observed cell here) it moved nothing.
TEST(Analytic, AFlatCropPullsTheBeliefIntoItByTheOutsideOffset) {
  for (const double nats : {0.0, 2.0, FilterConfig{}.outside_crop_nats}) {
    FilterConfig c = small_config();
    c.etu = c.mgr = c.pas = false;
    c.outside_crop_nats = nats;
    SeqLocFilter filter(c);
    Volume flat;
    flat.values.assign(static_cast<std::size_t>(7 * 9 * 16), 0.0F);
    filter.step(prepare_frame(flat.view(7, 9, 16), c.headings), {12, 10, 0}, {}, {});
    // Crop cells: u in [8, 16], v in [7, 13] (centre (12, 10), 9 x 7 cells, whole cells).
    const double inside = filter.belief().position_mass(12, 10), outside = filter.belief().position_mass(2, 2);
    EXPECT_NEAR(std::log(inside / outside), nats, 1e-4) << "offset " << nats;
  }
  EXPECT_GT(FilterConfig{}.outside_crop_nats, 0.0) << "the default must not leave a crop without pull";
}

TEST(Analytic, RelativeEtuCountsTypicalFramesFullyAndTempersFlatterOnes) {
  EXPECT_DOUBLE_EQ(etu_weight(0.9, 0.9), 1.0) << "a frame as sharp as the reference";
  EXPECT_DOUBLE_EQ(etu_weight(0.5, 0.9), 1.0) << "sharper: still 1, never more";
  EXPECT_NEAR(etu_weight(0.95, 0.9), 0.5, 1e-12) << "halfway to uniform from the reference";
  EXPECT_DOUBLE_EQ(etu_weight(1.0, 0.9), 1e-3) << "uniform";
  EXPECT_NEAR(etu_weight(0.95, 0.0), 0.05, 1e-12) << "the paper's ETU";
  EXPECT_GT(FilterConfig{}.etu_reference_entropy, 0.0) << "the default is ours (docs/filter.md)";
}

TEST(Analytic, EtuWeightOfUniformAndDelta) {
  Volume uniform;
  uniform.values.assign(9 * 11 * 16, -3.0f);
  const auto u = prepare_frame(uniform.view(9, 11, 16), 16);
  EXPECT_NEAR(u.entropy, 1.0, 1e-6);
  EXPECT_DOUBLE_EQ(etu_weight(u.entropy), 1e-3);
  EXPECT_EQ(u.max_log_prob, *std::max_element(u.log_prob.begin(), u.log_prob.end()));
  const auto d = prepare_frame(delta_volume(9, 11, 16, 1, 1, 1).view(9, 11, 16), 16);
  EXPECT_EQ(d.max_log_prob, 0.0f) << "all the mass in one cell";
  EXPECT_NEAR(d.entropy, 0.0, 1e-9);
  EXPECT_DOUBLE_EQ(etu_weight(d.entropy), 1.0);
}

TEST(Analytic, MgrKeepsEverySuppressedCellAtLeastEpsQ) {
  FilterConfig c = small_config();
  SeqLocFilter filter(c);
  std::vector<float> road(static_cast<std::size_t>(c.width * c.height));
  for (int v = 0; v < c.height; ++v)
    for (int u = 0; u < c.width; ++u) road[static_cast<std::size_t>(v * c.width + u)] = static_cast<float>(std::abs(v - 10));
  // A very confident frame elsewhere suppresses most cells to nothing, but not below eps q.
  const Volume d = delta_volume(9, 11, 16, 2, 2, 3);
  filter.step(prepare_frame(d.view(9, 11, 16), c.headings), {12, 10, 0}, {}, road);
  const auto log_q = road_prior_log_q(road, c.width, c.height, c.headings, c.mgr_sigma_m);
  for (int k = 0; k < c.headings; ++k)
    for (std::size_t i = 0; i < log_q.size(); ++i) {
      ASSERT_GE(filter.belief().slice(k)[i], c.mgr_epsilon * std::exp(log_q[i]) * (1 - 1e-6));
    }
}

TEST(Analytic, PasOfSymmetricAndAsymmetricPeaks) {
  BeliefVolume b(16, 16, 4);
  std::fill(b.data(), b.data() + b.size(), 0.0f);
  for (int k = 0; k < 4; ++k) {
    b.prob(8, 8, k) = 0.1f;
    b.prob(7, 8, k) = b.prob(9, 8, k) = b.prob(8, 7, k) = b.prob(8, 9, k) = 0.05f;
  }
  Pose p = peak_anchored_position(b, 8, 8, 3);
  EXPECT_NEAR(p.u, 8.0, 1e-9);
  EXPECT_NEAR(p.v, 8.0, 1e-9);
  // Heavier to the east: the exact weighted mean.
  for (int k = 0; k < 4; ++k) b.prob(10, 8, k) = 0.07f;
  p = peak_anchored_position(b, 8, 8, 3);
  const double m8 = 0.4, m_side = 0.2, m10 = 0.28;
  const double expected_u = (8 * m8 + 7 * m_side + 9 * m_side + 8 * m_side * 2 + 10 * m10) / (m8 + 4 * m_side + m10);
  EXPECT_NEAR(p.u, expected_u, 1e-6);
  EXPECT_GT(p.u, 8.0);
  EXPECT_NEAR(p.v, 8.0, 1e-6);
  // Radius 1 does not see the cell at u = 10.
  EXPECT_NEAR(peak_anchored_position(b, 8, 8, 1).u, 8.0, 1e-9);
}

TEST(Intake, MinusInfinityIsAZeroWithoutNaN) {
  FilterConfig c = small_config();
  c.mgr = false;  // nothing lifts the zeros: the hardest case
  SeqLocFilter filter(c);
  std::mt19937 rng(3);
  for (int step = 0; step < 4; ++step) {
    Volume vol = random_volume(rng, 9, 11, 16);
    for (std::size_t i = 0; i < vol.values.size(); i += 3) vol.values[i] = -std::numeric_limits<float>::infinity();
    filter.step(prepare_frame(vol.view(9, 11, 16), c.headings), {12, 10, 0}, {2, 0, 30}, {});
    for (std::size_t i = 0; i < filter.belief().size(); ++i) {
      ASSERT_TRUE(std::isfinite(filter.belief().data()[i]) && filter.belief().data()[i] >= 0) << i;
    }
    EXPECT_NEAR(filter.belief().total_probability(), 1.0, 1e-4);
  }
}

// float_to_half against a brute-force reference: the nearest of all finite halves (their bit
// patterns are ordered like their values for a given sign), ties to the even pattern.
TEST(Half, FloatToHalfIsTheNearestHalfTiesToEven) {
  for (std::uint32_t h = 0; h < 0x7C00; ++h) {  // every finite half comes back as itself
    ASSERT_EQ(float_to_half(half_to_float(static_cast<std::uint16_t>(h))), h) << h;
    ASSERT_EQ(float_to_half(-half_to_float(static_cast<std::uint16_t>(h))), h | 0x8000u) << h;
  }
  auto reference = [](float f) -> std::uint16_t {
    const auto sign = static_cast<std::uint16_t>(std::signbit(f) ? 0x8000 : 0);
    const double a = std::abs(static_cast<double>(f));
    if (a >= 65520.0) return sign | 0x7C00;
    std::uint32_t lo = 0, hi = 0x7BFF;  // the largest half <= a
    while (lo < hi) {
      const std::uint32_t mid = (lo + hi + 1) / 2;
      if (half_to_float(static_cast<std::uint16_t>(mid)) <= a) lo = mid; else hi = mid - 1;
    }
    if (lo == 0x7BFF) return static_cast<std::uint16_t>(sign | lo);
    const double below = half_to_float(static_cast<std::uint16_t>(lo)), above = half_to_float(static_cast<std::uint16_t>(lo + 1));
    const std::uint32_t h = (a - below < above - a || (a - below == above - a && (lo & 1u) == 0)) ? lo : lo + 1;
    return static_cast<std::uint16_t>(sign | h);
  };
  std::mt19937 rng(7);
  std::uniform_int_distribution<std::uint32_t> any_bits;
  for (int i = 0; i < 200000; ++i) {
    std::uint32_t bits = any_bits(rng);
    if ((bits & 0x7F800000u) == 0x7F800000u) continue;  // inf and NaN below
    if (i % 2 == 0) bits = (bits & 0x80FFFFFFu) | ((100u + bits % 45u) << 23);  // exponents near the half's range
    float f = 0;
    std::memcpy(&f, &bits, 4);
    ASSERT_EQ(float_to_half(f), reference(f)) << f;
  }
  // Exact ties: halfway between neighbours goes to the even one, in normal and subnormal range.
  for (std::uint16_t h : {std::uint16_t{0x0001}, std::uint16_t{0x0002}, std::uint16_t{0x03FF}, std::uint16_t{0x3C00},
                          std::uint16_t{0x3C01}, std::uint16_t{0x7BFE}}) {
    const float mid = (half_to_float(h) + half_to_float(static_cast<std::uint16_t>(h + 1))) / 2;
    EXPECT_EQ(float_to_half(mid), (h & 1) ? h + 1 : h) << h;
  }
  EXPECT_EQ(float_to_half(std::ldexp(1.0f, -25)), 0);
  EXPECT_EQ(float_to_half(65519.0f), 0x7BFF);
  EXPECT_EQ(float_to_half(65520.0f), 0x7C00);
  EXPECT_EQ(float_to_half(-std::numeric_limits<float>::infinity()), 0xFC00);
  EXPECT_TRUE(std::isnan(half_to_float(float_to_half(std::numeric_limits<float>::quiet_NaN()))));
}

// The plain-code conversions (builds without F16C) give the same bits as the ones this build
// runs, for every half and for floats of every exponent the halves can reach and beyond.
TEST(Half, PortableConversionsMatch) {
  for (std::uint32_t h = 0; h < 0x10000; ++h) {
    const auto half = static_cast<std::uint16_t>(h);
    const float a = half_to_float(half), b = detail::half_to_float_portable(half);
    if (std::isnan(a)) {
      EXPECT_TRUE(std::isnan(b)) << h;
      continue;
    }
    ASSERT_EQ(std::memcmp(&a, &b, 4), 0) << h;
  }
  std::mt19937 rng(11);
  std::uniform_int_distribution<std::uint32_t> any_bits;
  for (int i = 0; i < 200000; ++i) {
    std::uint32_t bits = any_bits(rng);
    if ((bits & 0x7F800000u) == 0x7F800000u) continue;  // inf and NaN: payloads may differ
    if (i % 2 == 0) bits = (bits & 0x80FFFFFFu) | ((95u + bits % 50u) << 23);
    float f = 0;
    std::memcpy(&f, &bits, 4);
    ASSERT_EQ(float_to_half(f), detail::float_to_half_portable(f)) << f;
  }
  EXPECT_EQ(detail::float_to_half_portable(std::numeric_limits<float>::infinity()), 0x7C00);
  EXPECT_TRUE(std::isnan(detail::half_to_float_portable(detail::float_to_half_portable(std::nanf("")))));
}

// The array conversions give the one-value ones' results for every half and for random floats,
// at every offset and length (the vector loop's remainder), and refuse arrays of unequal length.
TEST(Half, ArrayConversionsMatchTheOneValueOnes) {
  std::vector<std::uint16_t> halves(0x10000);
  for (std::uint32_t h = 0; h < 0x10000; ++h) halves[h] = static_cast<std::uint16_t>(h);
  std::vector<float> floats(halves.size());
  halves_to_floats(halves, floats);
  for (std::uint32_t h = 0; h < 0x10000; ++h) {
    const float one = half_to_float(static_cast<std::uint16_t>(h));
    if (std::isnan(one)) {
      EXPECT_TRUE(std::isnan(floats[h])) << h;
      continue;
    }
    ASSERT_EQ(std::memcmp(&one, &floats[h], 4), 0) << h;
  }
  std::mt19937 rng(5);
  std::uniform_int_distribution<std::uint32_t> any_bits;
  std::vector<float> values(4099);
  for (float& f : values) {
    std::uint32_t bits = any_bits(rng);
    if ((bits & 0x7F800000u) == 0x7F800000u) bits &= 0xBFFFFFFFu;  // no inf or NaN: their payloads may differ
    bits = (bits & 0x80FFFFFFu) | ((95u + bits % 50u) << 23);
    std::memcpy(&f, &bits, 4);
  }
  for (std::size_t offset : {0, 1, 3}) {
    for (std::size_t n : {0, 1, 7, 8, 9, 4096}) {
      const std::span<const float> in(values.data() + offset, n);
      std::vector<std::uint16_t> out(n);
      floats_to_halves(in, out);
      for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(out[i], float_to_half(in[i])) << offset << " " << n << " " << i;
      std::vector<float> back(n);
      halves_to_floats(out, back);
      for (std::size_t i = 0; i < n; ++i) ASSERT_EQ(back[i], half_to_float(out[i])) << offset << " " << n << " " << i;
    }
  }
  std::vector<std::uint16_t> short_out(3);
  try {
    floats_to_halves(std::span<const float>(values.data(), 4), short_out);
    ADD_FAILURE() << "arrays of unequal length were converted";
  } catch (const Error& e) {
    EXPECT_EQ(e.category(), ErrorCategory::internal) << "a caller's bug, not the data's";
  }
}

TEST(Config, ValidateNamesTheField) {
  FilterConfig c;
  c.mgr_epsilon = 1.5;
  try {
    c.validate();
    FAIL();
  } catch (const FilterError& e) {
    EXPECT_NE(std::string(e.what()).find("mgr_epsilon = 1.5"), std::string::npos) << e.what();
  }
  c = FilterConfig{};
  c.pas_radius = -1;
  EXPECT_THROW(c.validate(), FilterError);
  c = FilterConfig{};
  c.threads = 0;
  EXPECT_THROW(SeqLocFilter{c}, FilterError);
  FilterConfig ok;
  EXPECT_NO_THROW(ok.validate());
  EXPECT_EQ(ok.headings, 256);
  EXPECT_DOUBLE_EQ(ok.mgr_epsilon, 0.01);
  EXPECT_EQ(ok.pas_radius, 3);
}

}  // namespace
}  // namespace seqloc::filter
