#include "seqloc/pipeline/forward_filter.hpp"

#include <type_traits>
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

class ForwardFilter::Backend {
 public:
  virtual ~Backend() = default;
  virtual void reset_uniform() = 0;
  virtual void reset_gaussian(double u, double v, double sigma_m) = 0;
  virtual filter::FrameResult step(const filter::PreparedFrame& frame, const filter::CropPose& crop,
                                   const filter::Odometry& odometry, std::span<const float> road_distance_m,
                                   const std::optional<filter::GpsFix>& gps) = 0;
  virtual void recentre(int du, int dv) = 0;
  virtual void rebase(filter::BeliefVolume belief, const std::optional<filter::Pose>& last_estimate) = 0;
  [[nodiscard]] virtual const std::optional<filter::Pose>& last_estimate() const = 0;
  [[nodiscard]] virtual const filter::BeliefVolume& belief() const = 0;
};

namespace {

// A filter (filter::SeqLocFilter or gpu::DeviceFilter, whose steps make the same decisions through
// filter::StepDecisions) as ForwardFilter's backend.
template <class Filter>
class Adapter final : public ForwardFilter::Backend {
 public:
  template <class... Args>
  explicit Adapter(Args&&... args) : filter_(std::forward<Args>(args)...) {}
  void reset_uniform() override { filter_.reset_uniform(); }
  void reset_gaussian(double u, double v, double sigma_m) override { filter_.reset_gaussian(u, v, sigma_m); }
  filter::FrameResult step(const filter::PreparedFrame& frame, const filter::CropPose& crop,
                           const filter::Odometry& odometry, std::span<const float> road_distance_m,
                           const std::optional<filter::GpsFix>& gps) override {
    return filter_.step(frame, crop, odometry, road_distance_m, gps);
  }
  void recentre(int du, int dv) override { filter_.recentre(du, dv); }
  void rebase(filter::BeliefVolume belief, const std::optional<filter::Pose>& last_estimate) override {
    filter_.rebase(std::move(belief), last_estimate);
  }
  [[nodiscard]] const std::optional<filter::Pose>& last_estimate() const override { return filter_.last_estimate(); }
  [[nodiscard]] const filter::BeliefVolume& belief() const override {
    if constexpr (std::is_same_v<decltype(filter_.belief()), const filter::BeliefVolume&>) {
      return filter_.belief();
    } else {
      copy_ = filter_.belief();  // a device's belief, copied to the host
      return *copy_;
    }
  }

 private:
  Filter filter_;
  mutable std::optional<filter::BeliefVolume> copy_;
};

}  // namespace

ForwardFilter::ForwardFilter(const filter::FilterConfig& config, Device device) : device_(device) {
  if (device == Device::cpu) {
    backend_ = std::make_unique<Adapter<filter::SeqLocFilter>>(config);
  } else {
    backend_ = std::make_unique<Adapter<gpu::DeviceFilter>>(
        config, device == Device::cuda ? gpu::Backend::cuda : gpu::Backend::host);
  }
}

ForwardFilter::~ForwardFilter() = default;
ForwardFilter::ForwardFilter(ForwardFilter&&) noexcept = default;
ForwardFilter& ForwardFilter::operator=(ForwardFilter&&) noexcept = default;

void ForwardFilter::reset_uniform() { backend_->reset_uniform(); }

void ForwardFilter::reset_gaussian(double u, double v, double sigma_m) { backend_->reset_gaussian(u, v, sigma_m); }

filter::FrameResult ForwardFilter::step(const filter::PreparedFrame& frame, const filter::CropPose& crop,
                                        const filter::Odometry& odometry, std::span<const float> road_distance_m,
                                        const std::optional<filter::GpsFix>& gps) {
  return backend_->step(frame, crop, odometry, road_distance_m, gps);
}

void ForwardFilter::recentre(int du, int dv) { backend_->recentre(du, dv); }

void ForwardFilter::rebase(filter::BeliefVolume belief, const std::optional<filter::Pose>& last_estimate) {
  backend_->rebase(std::move(belief), last_estimate);
}

const std::optional<filter::Pose>& ForwardFilter::last_estimate() const { return backend_->last_estimate(); }

const filter::BeliefVolume& ForwardFilter::belief() const { return backend_->belief(); }

}  // namespace seqloc::pipeline
