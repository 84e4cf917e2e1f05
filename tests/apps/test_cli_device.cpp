// seqloc localize --device: the CUDA backend's kernels run on the CPU (cuda-host) give the CPU
// filter's poses through the whole pipeline (window moves, smoothing, lags); --device cuda where no
// GPU is usable stops before any work with one line.

#include <cmath>
#include <sstream>
#include <string>
#include <vector>

#include <gtest/gtest.h>

#include "seqloc/gpu/device_filter.hpp"
#include "support/test_support.hpp"

namespace seqloc {
namespace {

using test::run_seqloc;

struct Pose {
  double x, y, heading;
};

// x_m, y_m and heading_deg of every row of a poses.csv (docs/route-format.md).
std::vector<Pose> read_poses(const std::filesystem::path& path) {
  std::istringstream in(test::read_file(path));
  std::string line;
  std::getline(in, line);
  std::vector<std::string> header;
  for (std::istringstream h(line); std::getline(h, line, ',');) header.push_back(line);
  auto column = [&](const std::string& name) {
    for (std::size_t i = 0; i < header.size(); ++i)
      if (header[i] == name) return i;
    ADD_FAILURE() << path << ": no column " << name;
    return std::size_t{0};
  };
  const std::size_t cx = column("x_m"), cy = column("y_m"), ch = column("heading_deg");
  std::vector<Pose> poses;
  while (std::getline(in, line)) {
    std::vector<std::string> f;
    for (std::istringstream r(line); std::getline(r, line, ',');) f.push_back(line);
    poses.push_back({std::stod(f.at(cx)), std::stod(f.at(cy)), std::stod(f.at(ch))});
  }
  return poses;
}

// The sample region and one simulated route (ctest runs each test in its own process: no suite-wide
// fixture would be shared).
class CliDevice : public ::testing::Test {
 protected:
  void SetUp() override {
    cache_ = (dir_ / "sample.gpkg").string();
    auto r = run_seqloc({"preprocess", std::string(SEQLOC_SOURCE_DIR) + "/samples/rural-valley.osm.pbf", "-o", cache_});
    ASSERT_EQ(r.exit_code, 0) << r.err;
    routes_ = (dir_ / "routes").string();
    r = run_seqloc({"simulate", cache_, "-o", routes_, "--routes", "1", "--frames", "24", "--seed", "11"});
    ASSERT_EQ(r.exit_code, 0) << r.err;
  }
  test::ScratchDir dir_;
  std::string cache_, routes_;
};

TEST_F(CliDevice, CudaHostGivesTheCpuPosesInEveryForwardMode) {
  if (!gpu::built_with_cuda()) GTEST_SKIP() << gpu::cuda_status().reason;
  const std::vector<std::string> common{"localize", cache_, routes_ + "/route_000", "--window", "96", "--mode", "all"};
  auto cpu = common, host = common, lagged_cpu = common, lagged_host = common;
  cpu.insert(cpu.end(), {"-o", (dir_ / "cpu").string()});
  host.insert(host.end(), {"-o", (dir_ / "host").string(), "--device", "cuda-host"});
  ASSERT_EQ(run_seqloc(cpu).exit_code, 0);
  const auto r = run_seqloc(host);
  ASSERT_EQ(r.exit_code, 0) << r.err;
  for (const char* mode : {"online", "seqloc", "smooth"}) {
    const auto a = read_poses(dir_ / "cpu/route_000" / mode / "poses.csv");
    const auto b = read_poses(dir_ / "host/route_000" / mode / "poses.csv");
    ASSERT_EQ(a.size(), 24u) << mode;
    ASSERT_EQ(b.size(), a.size()) << mode;
    for (std::size_t i = 0; i < a.size(); ++i) {
      // Within a tenth of a cell and of a bin: float rounding in another order, never a cell.
      EXPECT_NEAR(b[i].x, a[i].x, 0.05) << mode << " frame " << i;
      EXPECT_NEAR(b[i].y, a[i].y, 0.05) << mode << " frame " << i;
      EXPECT_NEAR(std::remainder(b[i].heading - a[i].heading, 360.0), 0.0, 0.1) << mode << " frame " << i;
    }
  }
}

TEST_F(CliDevice, CudaWithoutAUsableGpuStopsBeforeAnyWork) {
  const gpu::CudaStatus status = gpu::cuda_status();
  if (status.usable) GTEST_SKIP() << "a GPU is usable here: " << status.device_name;
  const auto out = dir_ / "out";
  const auto r = run_seqloc({"localize", cache_, routes_ + "/route_000", "-o", out.string(), "--device", "cuda"});
  EXPECT_EQ(r.exit_code, 1);
  EXPECT_NE(r.err.find("--device cuda: " + status.reason), std::string::npos) << r.err;
  EXPECT_EQ(std::count(r.err.begin(), r.err.end(), '\n'), 1) << r.err;
  EXPECT_EQ(r.out, "");
  EXPECT_FALSE(std::filesystem::exists(out));
  for (const auto& entry : std::filesystem::directory_iterator(dir_.path())) {
    EXPECT_EQ(entry.path().filename().string().find("out."), std::string::npos) << "temporary folder left";
  }
}

TEST_F(CliDevice, TheCudaBackendRefusesMotionNoiseUpFront) {
  if (!gpu::built_with_cuda()) GTEST_SKIP() << gpu::cuda_status().reason;
  const auto out = dir_ / "out";
  const auto r = run_seqloc(
      {"localize", cache_, routes_ + "/route_000", "-o", out.string(), "--device", "cuda-host", "--motion-noise"});
  EXPECT_EQ(r.exit_code, 2) << r.err;
  EXPECT_NE(r.err.find("motion noise"), std::string::npos) << r.err;
  EXPECT_FALSE(std::filesystem::exists(out));
}

}  // namespace
}  // namespace seqloc
