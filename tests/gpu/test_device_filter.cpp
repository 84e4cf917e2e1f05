// The CUDA backend (gpu/): DeviceFilter against the CPU filter on seeded random routes. The host
// backend runs the CUDA kernels' own code on the CPU, so these tests check the backend's
// arithmetic and its order of stages on every machine; the same comparisons run on the GPU where
// one is usable, and skip (saying why) where none is.

#include <algorithm>
#include <cmath>
#include <functional>
#include <random>
#include <string>
#include <vector>

#include <gtest/gtest-spi.h>
#include <gtest/gtest.h>

#include "seqloc/filter/seqloc_filter.hpp"
#include "seqloc/gpu/device_filter.hpp"

namespace seqloc::gpu {
namespace {

using filter::BeliefVolume;
using filter::CropPose;
using filter::FilterConfig;
using filter::FrameResult;
using filter::FrameVolume;
using filter::Odometry;
using filter::PreparedFrame;
using filter::SeqLocFilter;

struct Variant {
  const char* name;
  bool etu = true, mgr = true, pas = true, self_calibrate = true;
  double hold_share = 0.05;  ///< 0: the estimate's power on every frame
  double rotation_deg = 0;   ///< 0: axis-aligned crops (the translation path)
  double cell_m = 0.5;
  int bins = 16;
  double sharpen = 1;  ///< frames raised to this power (> 1: overconfident, releasing the hold)
  bool subbin = false, gps = false;
  bool etu_route_reference = true;
};

void PrintTo(const Variant& v, std::ostream* os) { *os << v.name; }

FilterConfig config_of(const Variant& p) {
  FilterConfig c;
  c.width = 40;
  c.height = 36;
  c.headings = 16;
  c.etu = p.etu;
  c.mgr = p.mgr;
  c.pas = p.pas;
  c.self_calibrate = p.self_calibrate;
  c.self_calibration_hold_share = p.hold_share;
  c.subbin_heading = p.subbin;
  c.gps_prior = p.gps;
  c.etu_route_reference = p.etu_route_reference;
  return c;
}

/// A frame with a broad ridge (a road seen from a car: long along its heading) plus noise.
PreparedFrame ridge_frame(std::mt19937& rng, int h, int w, int bins, double cell_m, double sharpen, int headings) {
  std::normal_distribution<float> noise(0.0f, 0.7f);
  std::vector<float> values(static_cast<std::size_t>(h) * w * bins);
  const double cu = (w - 1) / 2.0 + 1.3, cv = (h - 1) / 2.0 - 0.7;
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u)
      for (int j = 0; j < bins; ++j) {
        const double across = (u - cu) * 0.8 + (v - cv) * 0.6, along = (u - cu) * -0.6 + (v - cv) * 0.8;
        const double heading = std::min(j, bins - j);
        const double log_p = -across * across / 4 - along * along / 200 - heading * heading / 6 + noise(rng);
        values[(static_cast<std::size_t>(v) * w + u) * bins + j] = static_cast<float>(sharpen * log_p);
      }
  FrameVolume view;
  view.data = values.data();
  view.height = h;
  view.width = w;
  view.bins = bins;
  view.cell_m = cell_m;
  view.values = filter::VolumeValues::log_prob;
  return filter::prepare_frame(view, headings);
}

/// The two beliefs agree where the mass is: each cell holding at least 1e-6 of the peak has the
/// same log-probability within 1e-3 (float rounding in another order gives ~1e-5 after a dozen
/// steps; a wrong weight, index or bin gives >= 1e-2 on these inputs).
void expect_same_belief(const BeliefVolume& device, const BeliefVolume& cpu, const std::string& what) {
  const float peak = *std::max_element(cpu.data(), cpu.data() + cpu.size());
  int compared = 0;
  for (std::size_t i = 0; i < cpu.size(); ++i) {
    const float c = cpu.data()[i], d = device.data()[i];
    if (c < 1e-6f * peak) continue;
    ++compared;
    ASSERT_GT(d, 0.0f) << what << ": cell " << i;
    ASSERT_NEAR(std::log(d), std::log(c), 1e-3) << what << ": cell " << i << " of " << cpu.size();
  }
  ASSERT_GT(compared, 0) << what;
}

void expect_same_result(const FrameResult& d, const FrameResult& c, const std::string& what) {
  EXPECT_EQ(d.argmax.u, c.argmax.u) << what;
  EXPECT_EQ(d.argmax.v, c.argmax.v) << what;
  EXPECT_EQ(d.argmax.heading_deg, c.argmax.heading_deg) << what;
  EXPECT_NEAR(d.pose.u, c.pose.u, 1e-3) << what;
  EXPECT_NEAR(d.pose.v, c.pose.v, 1e-3) << what;
  EXPECT_NEAR(d.pose.heading_deg, c.pose.heading_deg, 1e-3) << what;
  EXPECT_NEAR(d.volume_power, c.volume_power, 1e-4 * c.volume_power) << what;
  EXPECT_NEAR(d.etu_weight, c.etu_weight, 1e-5) << what;
  EXPECT_NEAR(d.frame_entropy, c.frame_entropy, 1e-5) << what;
  EXPECT_NEAR(d.peak_log_belief, c.peak_log_belief, 1e-3) << what;
  EXPECT_EQ(d.relocalized, c.relocalized) << what;
}

/// What a route exercised, for checks that the variant reached the path it is meant to.
struct Exercised {
  bool powered = false;   ///< some frame went in at a power other than 1
  bool released = false;  ///< the hold released (the belief was raised once)
};

/// The CPU filter and the backend side by side over a seeded route; `plant` (when given) changes
/// the backend's configuration alone, to show that the comparisons catch a decision made otherwise.
Exercised compare_route(const Variant& p, Backend backend, int steps,
                        const std::function<void(FilterConfig&)>& plant = {}) {
  const FilterConfig c = config_of(p);
  FilterConfig planted = c;
  if (plant) plant(planted);
  std::mt19937 rng(4242);
  std::uniform_real_distribution<double> unit(0, 1);
  std::vector<float> road(static_cast<std::size_t>(c.width) * c.height);
  for (int v = 0; v < c.height; ++v)
    for (int u = 0; u < c.width; ++u)
      road[static_cast<std::size_t>(v) * c.width + u] = static_cast<float>(std::abs(0.6 * u - 0.8 * v + 4) * 0.5);
  SeqLocFilter cpu(c);
  DeviceFilter device(planted, backend);
  Exercised seen;
  for (int step = 0; step < steps; ++step) {
    const int h = 15 + step % 3, w = 17 - step % 2;
    const PreparedFrame frame = ridge_frame(rng, h, w, p.bins, p.cell_m, p.sharpen, c.headings);
    const CropPose crop{16 + 6 * unit(rng), 14 + 6 * unit(rng), p.rotation_deg == 0 ? 0.0 : p.rotation_deg + 10 * step};
    const Odometry odo{2.5 * unit(rng), unit(rng) - 0.5, 40 * unit(rng) - 20};
    std::optional<filter::GpsFix> fix = filter::GpsFix{18 + 2 * unit(rng), 16 + 2 * unit(rng), 6};
    if (!p.gps) fix.reset();
    const std::string what = std::string(p.name) + " (" + backend_name(backend) + ") step " + std::to_string(step);
    if (step == 5) {  // the window follows the vehicle
      cpu.recentre(2, -1);
      device.recentre(2, -1);
    }
    const FrameResult a = cpu.step(frame, crop, odo, road, fix);
    const FrameResult b = device.step(frame, crop, odo, road, fix);
    expect_same_result(b, a, what);
    expect_same_belief(device.belief(), cpu.belief(), what);
    if (::testing::Test::HasFatalFailure()) return seen;
    seen.powered = seen.powered || a.volume_power != 1.0;
    seen.released = seen.released || !cpu.calibration().held();
  }
  return seen;
}

class DeviceAgainstCpu : public ::testing::TestWithParam<Variant> {};

TEST_P(DeviceAgainstCpu, HostBackendAgreesOnSeededRoutes) {
  const Variant& p = GetParam();
  if (!built_with_cuda()) GTEST_SKIP() << cuda_status().reason;
  const Exercised seen = compare_route(p, Backend::host, 12);
  if (p.sharpen > 1 && p.self_calibrate) {
    EXPECT_TRUE(seen.powered) << "overconfident frames must be powered down";
    if (p.hold_share > 0) {
      EXPECT_TRUE(seen.released) << "and release the hold (the belief raised once)";
    }
  }
}

// The comparisons have teeth: a backend whose ETU decides otherwise (here the backend weighs each
// frame against the configured reference entropy while the CPU weighs against the route's) fails
// them on ETU's weight, and on the beliefs that follow.
TEST(DeviceAgainstCpuCheck, APlantedDifferenceInOneBackendsEtuIsCaught) {
  if (!built_with_cuda()) GTEST_SKIP() << cuda_status().reason;
  ::testing::TestPartResultArray failures;
  {
    const ::testing::ScopedFakeTestPartResultReporter intercept(
        ::testing::ScopedFakeTestPartResultReporter::INTERCEPT_ONLY_CURRENT_THREAD, &failures);
    (void)compare_route(Variant{"planted_etu"}, Backend::host, 6,
                        [](FilterConfig& c) { c.etu_route_reference = false; });
  }
  int on_etu = 0;
  for (int i = 0; i < failures.size(); ++i) {
    on_etu += std::string(failures.GetTestPartResult(i).message()).find("etu_weight") != std::string::npos;
  }
  EXPECT_GT(on_etu, 0) << failures.size() << " failures, none on ETU's weight";
  // And the same route without the plant passes: the failures are the plant's.
  const Exercised clean = compare_route(Variant{"unplanted"}, Backend::host, 6);
  (void)clean;
}

TEST_P(DeviceAgainstCpu, CudaBackendAgreesOnSeededRoutes) {
  const Variant& p = GetParam();
  const CudaStatus status = cuda_status();
  if (!status.usable) GTEST_SKIP() << "no usable GPU: " << status.reason;
  compare_route(p, Backend::cuda, 12);
}

INSTANTIATE_TEST_SUITE_P(
    Gpu, DeviceAgainstCpu,
    ::testing::Values(Variant{"defaults"}, Variant{"naive", false, false, false, false},
                      Variant{.name = "overconfident", .sharpen = 4},
                      Variant{.name = "no_hold", .hold_share = 0, .sharpen = 2},
                      Variant{.name = "rotated_crop", .rotation_deg = 7.5},
                      Variant{.name = "coarse_volume", .cell_m = 1.0},
                      Variant{.name = "more_bins", .rotation_deg = 3, .bins = 32},
                      Variant{.name = "subbin_and_gps", .subbin = true, .gps = true},
                      Variant{.name = "paper_etu", .self_calibrate = false, .etu_route_reference = false}),
    [](const auto& variant) { return std::string(variant.param.name); });

TEST(DeviceFilter, ARefusedBackendSaysWhy) {
  const CudaStatus status = cuda_status();
  if (status.usable) GTEST_SKIP() << "a GPU is usable here (" << status.device_name << ")";
  EXPECT_FALSE(status.reason.empty());
  try {
    DeviceFilter f(FilterConfig{}, Backend::cuda);
    FAIL() << "the CUDA backend started without a usable GPU";
  } catch (const filter::FilterError& e) {
    EXPECT_NE(std::string(e.what()).find(status.reason), std::string::npos) << e.what();
  }
}

TEST(DeviceFilter, MotionNoiseIsRefusedNotIgnored) {
  FilterConfig c;
  c.motion_noise = true;
  EXPECT_THROW(DeviceFilter(c, Backend::host), filter::FilterError);
}

TEST(DeviceFilter, TheSelfCalibrationBankIsRefusedNotIgnored) {
  // Refused for what it is, before anything asks whether a backend can run at all.
  FilterConfig c;
  c.self_calibration_bank = true;
  try {
    DeviceFilter f(c, Backend::host);
    FAIL() << "the CUDA backend took a configuration with the self-calibration bank";
  } catch (const filter::FilterError& e) {
    EXPECT_NE(std::string(e.what()).find("self-calibration bank"), std::string::npos) << e.what();
  }
  if (!built_with_cuda()) return;  // without CUDA no backend starts, whatever its configuration
  c.self_calibrate = false;        // the bank is part of self-calibration: off with it
  EXPECT_NO_THROW(DeviceFilter(c, Backend::host));
}

TEST(DeviceFilter, SetBeliefChecksTheWindow) {
  if (!built_with_cuda()) GTEST_SKIP() << cuda_status().reason;
  FilterConfig c;
  c.width = 12;
  c.height = 10;
  c.headings = 8;
  DeviceFilter f(c, Backend::host);
  EXPECT_THROW(f.set_belief(BeliefVolume(10, 12, 8)), filter::FilterError);
  BeliefVolume b(12, 10, 8);
  b.set_gaussian(3, 2, 1.5);
  f.set_belief(b);
  const BeliefVolume back = f.belief();
  EXPECT_TRUE(std::equal(b.data(), b.data() + b.size(), back.data()));
}

}  // namespace
}  // namespace seqloc::gpu
