#include "seqloc/pipeline/forward_filter.hpp"

#include <utility>

namespace seqloc::pipeline {

const char* device_name(Device device) {
  switch (device) {
    case Device::cpu:
      return "cpu";
    case Device::cuda:
      return "cuda";
    case Device::cuda_host:
      return "cuda-host";
  }
  return "?";
}

std::optional<Device> device_from_name(const std::string& name) {
  for (const Device d : {Device::cpu, Device::cuda, Device::cuda_host})
    if (name == device_name(d)) return d;
  return std::nullopt;
}

void check_device(Device device, const filter::FilterConfig& config) {
  if (device == Device::cpu) return;
  const gpu::CudaStatus status = gpu::cuda_status();
  const bool runs = device == Device::cuda ? status.usable : gpu::built_with_cuda();
  if (!runs) {
    throw filter::FilterError(std::string("--device ") + device_name(device) + ": " + status.reason, ErrorCategory::io);
  }
  if (config.motion_noise) {
    throw filter::FilterError(std::string("--device ") + device_name(device) +
                                  ": the CUDA backend has no motion noise yet (run it on the CPU)",
                              ErrorCategory::usage);
  }
}

ForwardFilter::ForwardFilter(const filter::FilterConfig& config, Device device) : device_(device) {
  if (device == Device::cpu) {
    cpu_.emplace(config);
  } else {
    gpu_ =
        std::make_unique<gpu::DeviceFilter>(config, device == Device::cuda ? gpu::Backend::cuda : gpu::Backend::host);
  }
}

void ForwardFilter::reset_uniform() {
  if (cpu_) {
    cpu_->reset_uniform();
  } else {
    gpu_->reset_uniform();
  }
}

void ForwardFilter::reset_gaussian(double u, double v, double sigma_m) {
  if (cpu_) {
    cpu_->reset_gaussian(u, v, sigma_m);
  } else {
    gpu_->reset_gaussian(u, v, sigma_m);
  }
}

filter::FrameResult ForwardFilter::step(const filter::PreparedFrame& frame, const filter::CropPose& crop,
                                        const filter::Odometry& odometry, std::span<const float> road_distance_m,
                                        const std::optional<filter::GpsFix>& gps) {
  return cpu_ ? cpu_->step(frame, crop, odometry, road_distance_m, gps)
              : gpu_->step(frame, crop, odometry, road_distance_m, gps);
}

void ForwardFilter::recentre(int du, int dv) {
  if (cpu_) {
    cpu_->recentre(du, dv);
  } else {
    gpu_->recentre(du, dv);
  }
}

void ForwardFilter::rebase(filter::BeliefVolume belief, const std::optional<filter::Pose>& last_estimate) {
  if (cpu_) {
    cpu_->rebase(std::move(belief), last_estimate);
  } else {
    gpu_->rebase(belief, last_estimate);
  }
}

const std::optional<filter::Pose>& ForwardFilter::last_estimate() const {
  return cpu_ ? cpu_->last_estimate() : gpu_->last_estimate();
}

const filter::BeliefVolume& ForwardFilter::belief() const {
  if (cpu_) return cpu_->belief();
  copy_ = gpu_->belief();
  return *copy_;
}

}  // namespace seqloc::pipeline
