#pragma once
// The SeqLoc filter with its belief resident on a CUDA device (docs/gpu.md).
//
// DeviceFilter runs the step SeqLocFilter runs (seqloc_filter.hpp), with the same FilterConfig
// and the same results up to float rounding: motion, crop intake, ETU, self-calibration, MGR,
// normalization, PAS and the sub-bin heading. The belief never leaves the device during a step;
// what crosses to the host is a handful of scalars, the pose's neighbourhood for PAS, and (with
// self-calibration on) the evidence's depth histograms (4 x 4,001 fixed-point sums, made on the
// device with the CPU filter's per-cell arithmetic), from which the host estimates the power.
//
// The kernels are written once over an execution space: Backend::cuda runs them on the GPU,
// Backend::host runs the very same kernels one element at a time on the CPU. The host backend is
// what the test suite checks against SeqLocFilter on machines without a GPU (CI's); it is not a
// fast path.
//
// Not on the device yet: motion noise (FilterConfig::motion_noise; refused), the smoother's
// backward step, and frames handed over as device arrays (frames are PreparedFrame, uploaded).

#include <memory>
#include <optional>
#include <span>
#include <string>

#include "seqloc/filter/belief.hpp"
#include "seqloc/filter/config.hpp"
#include "seqloc/filter/self_calibration.hpp"
#include "seqloc/filter/seqloc_filter.hpp"
#include "seqloc/filter/types.hpp"

namespace seqloc::gpu {

/// Whether this build and this machine can run the CUDA backend.
struct CudaStatus {
  bool usable = false;
  /// Why not, in one line (a build without CUDA, no driver, a driver older than the runtime, no
  /// device); empty when usable.
  std::string reason;
  std::string device_name;       ///< device 0's name, when usable
  int compute_capability = 0;    ///< major * 10 + minor
  std::size_t memory_bytes = 0;  ///< device 0's global memory
};

/// Whether the library was compiled with CUDA (nvcc found at configure time).
[[nodiscard]] bool built_with_cuda();

/// Asks the CUDA runtime (once per process; the answer is cached).
[[nodiscard]] CudaStatus cuda_status();

enum class Backend {
  cuda,  ///< the GPU (device 0)
  host,  ///< the same kernels on the CPU, one element at a time: for tests
};

/// "cuda" or "host".
[[nodiscard]] const char* backend_name(Backend backend);

/// The median time (ms) of `repeats` copies of `bytes` within the backend's memory (device to
/// device on the GPU): the peer that benchmarks measure a step against. Throws as DeviceFilter.
[[nodiscard]] double copy_ms(Backend backend, std::size_t bytes, int repeats);

class DeviceFilter : private filter::CellWork {
 public:
  /// Allocates the belief and its buffers on the backend. Throws filter::FilterError: io when the
  /// backend cannot run (naming cuda_status().reason) or device memory runs out, usage for a
  /// configuration it does not support (motion noise).
  DeviceFilter(const filter::FilterConfig& config, Backend backend);
  ~DeviceFilter() override;
  DeviceFilter(const DeviceFilter&) = delete;
  DeviceFilter& operator=(const DeviceFilter&) = delete;

  [[nodiscard]] const filter::FilterConfig& config() const { return config_; }
  [[nodiscard]] Backend backend() const { return backend_; }

  /// As SeqLocFilter's.
  void reset_uniform();
  void reset_gaussian(double u, double v, double sigma_m);
  filter::FrameResult step(const filter::PreparedFrame& frame, const filter::CropPose& crop,
                           const filter::Odometry& odometry, std::span<const float> road_distance_m,
                           const std::optional<filter::GpsFix>& gps = std::nullopt) {
    return decisions_.step(*this, {frame, crop, road_distance_m, gps}, odometry);
  }
  void predict(const filter::Odometry& odometry) override;
  filter::FrameResult update(const filter::PreparedFrame& frame, const filter::CropPose& crop,
                             std::span<const float> road_distance_m,
                             const std::optional<filter::GpsFix>& gps = std::nullopt,
                             const std::optional<filter::FrameWeighting>& weighting = std::nullopt) {
    return decisions_.update(*this, {frame, crop, road_distance_m, gps}, weighting);
  }
  void recentre(int du, int dv);
  void rebase(const filter::BeliefVolume& belief, const std::optional<filter::Pose>& last_estimate);
  [[nodiscard]] const std::optional<filter::Pose>& last_estimate() const { return decisions_.last_estimate(); }
  [[nodiscard]] const filter::PowerEstimator& calibration() const { return decisions_.estimator(); }

  /// The belief, copied to the host (a whole window: for tests, pictures and the smoother, not
  /// for every frame).
  [[nodiscard]] filter::BeliefVolume belief() const;
  /// Replaces the belief (same size as the window; filter::FilterError otherwise).
  void set_belief(const filter::BeliefVolume& belief);

  class Engine;  ///< the kernels over one execution space (src/engine.hpp)

 private:
  /// A new sequence over the belief just set: no prediction before the next step, and
  /// self-calibration and ETU's route history start again.
  void start_sequence();
  // The cell work of a step in the engine (filter/cell_work.hpp), in the order StepDecisions calls it.
  void load(const filter::PreparedFrame& frame, bool estimating) override;
  filter::FrameShape powered_shape(const filter::PreparedFrame& frame, double power) override;
  void raise(float ratio) override;
  std::optional<filter::FrameShape> temper(const filter::PreparedFrame& frame, float exponent,
                                           std::optional<double> shape_power) override;
  double multiply_in(const filter::PreparedFrame& frame, const filter::CropPose& crop, float outside,
                     std::span<const float> gps_term, bool with_prior, bool pool) override;
  /// Self-calibration's evidence of the loaded frame against the pooled predicted belief.
  const filter::CalibrationEvidence& evidence(const filter::PreparedFrame& frame,
                                              const filter::CropPose& crop) override;
  filter::BeliefPeak normalize(double total, std::span<const float> road_distance_m) override;
  [[nodiscard]] filter::PositionMasses position_masses() override;
  [[nodiscard]] filter::CellValue cell_value() override;

  filter::FilterConfig config_;
  Backend backend_;
  filter::CalibrationEvidence evidence_;  // evidence()'s, its bins reused from frame to frame
  std::unique_ptr<Engine> engine_;
  filter::StepDecisions decisions_;  ///< every decision of the step (filter/step_decisions.hpp)
  std::optional<float> cached_min_;
  std::vector<float> road_;  ///< the road distances whose prior the engine holds
};

}  // namespace seqloc::gpu
