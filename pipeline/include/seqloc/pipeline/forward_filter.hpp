#pragma once
// The forward filter of the online, seqloc and smooth modes on the device a run chose
// (`seqloc localize --device`, docs/gpu.md): the CPU filter (filter::SeqLocFilter) or its CUDA
// backend (gpu::DeviceFilter), behind the few calls SequentialLocalizer makes.

#include <memory>
#include <optional>
#include <span>
#include <string>

#include "seqloc/filter/seqloc_filter.hpp"
#include "seqloc/gpu/device_filter.hpp"

namespace seqloc::pipeline {

enum class Device {
  cpu,        ///< filter::SeqLocFilter
  cuda,       ///< gpu::DeviceFilter on the GPU
  cuda_host,  ///< gpu::DeviceFilter's kernels run on the CPU (slow: for checking the backend without a GPU)
};

/// "cpu", "cuda", "cuda-host".
[[nodiscard]] const char* device_name(Device device);
/// The device a name gives; nothing for an unknown name.
[[nodiscard]] std::optional<Device> device_from_name(const std::string& name);

/// Throws filter::FilterError with one line saying why, unless `device` can run `config` here: the
/// CPU always can; cuda needs a build with CUDA and a usable GPU, cuda-host a build with CUDA (io
/// errors); neither has motion noise yet (usage).
void check_device(Device device, const filter::FilterConfig& config);

class ForwardFilter {
 public:
  ForwardFilter(const filter::FilterConfig& config, Device device);
  ~ForwardFilter();
  ForwardFilter(ForwardFilter&&) noexcept;
  ForwardFilter& operator=(ForwardFilter&&) noexcept;

  void reset_uniform();
  void reset_gaussian(double u, double v, double sigma_m);
  filter::FrameResult step(const filter::PreparedFrame& frame, const filter::CropPose& crop,
                           const filter::Odometry& odometry, std::span<const float> road_distance_m,
                           const std::optional<filter::GpsFix>& gps);
  void recentre(int du, int dv);
  void rebase(filter::BeliefVolume belief, const std::optional<filter::Pose>& last_estimate);
  [[nodiscard]] const std::optional<filter::Pose>& last_estimate() const;
  /// The belief after the last step (on a GPU: copied to the host on each call).
  [[nodiscard]] const filter::BeliefVolume& belief() const;
  [[nodiscard]] Device device() const { return device_; }

  /// The calls above, which every backend answers (forward_filter.cpp adapts each filter to them).
  class Backend;

 private:
  Device device_;
  std::unique_ptr<Backend> backend_;  ///< the one filter of the run, on its device
};

}  // namespace seqloc::pipeline
