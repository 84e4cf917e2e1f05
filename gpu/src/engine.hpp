#pragma once
// The kernels of DeviceFilter's step over one execution space (engine.cu): the belief and the
// frame live in the space's memory; the host hands in the per-step geometry and reads back
// scalars. Every kernel's per-cell arithmetic is filter/device_math.hpp's, shared with the CPU
// filter.

#include <cstddef>
#include <cstdint>
#include <memory>
#include <span>
#include <vector>

#include "seqloc/filter/config.hpp"
#include "seqloc/filter/device_math.hpp"
#include "seqloc/filter/self_calibration.hpp"
#include "seqloc/filter/seqloc_filter.hpp"
#include "seqloc/gpu/device_filter.hpp"

namespace seqloc::gpu {

/// The window bins' reading of the frame (filter/device_math.hpp).
using filter::math::HeadingBlend;

/// Where the window's cells read the frame: a translation (an axis-aligned crop of the window's
/// cell size, as seqloc's own crops are) or the general affine map.
struct CropGeometry {
  bool translate = true;
  filter::math::Translation translation;
  filter::math::CropMap map;
};

/// The belief's largest cell (first in [k][v][u] order among equals) and its least value.
struct PeakCell {
  int u = 0, v = 0, k = 0;
  float value = 0;
  float least = 0;
};

/// sum e^{k r} and sum e^{k r} r over a frame's cells, r the depth below its peak.
struct FrameSums {
  double z = 0, zr = 0;
};

/// How self-calibration judges the loaded frame against the pooled belief (what
/// filter::add_frame_cells and filter::coarse_evidence do on the host): the coarse grid's bins'
/// reading of the frame, where its cells lie in the frame, and the DepthHistogram's binning.
struct JudgeSetup {
  std::vector<HeadingBlend> blend;  ///< one per coarse bin
  CropGeometry geometry;            ///< coarse cells to frame cells
  int frame_stride = 1;             ///< the frame's bins binned: every frame_stride-th
  float peak = 0;                   ///< the frame's largest log-probability
  float max_depth = 0, per_nat = 0;
  int last_bin = 0;
  filter::DepthHistogram::Scale count_scale{}, mass_scale{};
};

/// The sums of a judgement: the frame's cells and the belief's mass in the crop by depth bin (in
/// DepthHistogram's fixed point), and the belief's mass and coarse cells outside the crop.
struct JudgeSums {
  std::vector<std::int64_t> frame_weight, frame_depth, mass_weight, mass_depth;
  double outside_mass = 0;
  std::uint64_t outside_cells = 0;
};

class DeviceFilter::Engine {
 public:
  virtual ~Engine() = default;

  virtual void upload_belief(const float* host) = 0;
  virtual void download_belief(float* host) const = 0;
  virtual void fill_belief(float value) = 0;
  [[nodiscard]] virtual float least() const = 0;

  /// The backward warp: window bin k reads source bins (k + s) % R and (k + s + 1) % R with
  /// weights 1 - a, a, each source bin j translated by `by_bin[j]`; `fill` outside the window.
  virtual void predict(std::span<const filter::math::Translation> by_bin, int s, float a, float fill) = 0;
  /// The window moves by whole cells (BeliefVolume::recentre).
  virtual void recentre(int du, int dv) = 0;
  /// The belief raised to `ratio`, renormalized; false (belief as it was) when that has no mass.
  virtual bool raise(float ratio) = 0;

  /// The frame's log-probabilities ([bin][v][u]) into the space's memory.
  virtual void load_frame(const filter::PreparedFrame& frame) = 0;
  /// sum e^{k r}, sum e^{k r} r over the loaded frame (r = log p - `peak`).
  [[nodiscard]] virtual FrameSums frame_sums(float power, float peak) const = 0;
  /// The loaded frame's cells as exp(`exponent` (log p - `peak`)), 0 where p is.
  virtual void temper(float exponent, float peak) = 0;
  /// The belief pooled onto self-calibration's coarse grid (filter::coarse_belief_for's size;
  /// math::pool_2x2 and math::pooled_weight), kept in the engine for judge().
  virtual void pool_coarse() = 0;
  /// The loaded frame's evidence against the pooled belief.
  [[nodiscard]] virtual JudgeSums judge(const JudgeSetup& setup) = 0;
  /// The pooled belief, copied to the host (for tests).
  virtual void download_coarse(filter::BeliefVolume& coarse) const = 0;
  /// b *= (or, without `with_prior`, b =) the tempered frame sampled at each window cell and bin
  /// (`outside` where the cell lies outside the crop), times `gps_factor` (W x H; empty for none).
  /// Returns the belief's total.
  virtual double multiply(std::span<const HeadingBlend> blend, const CropGeometry& geometry, float outside,
                          std::span<const float> gps_factor, bool with_prior) = 0;
  /// MGR's share eps q of every window cell from the road distances (W x H): made on the device
  /// (math::road_prior_share) and kept for normalize().
  virtual void set_road_prior(std::span<const float> distance_m, double sigma_m, float eps) = 0;
  /// b = b * keep, plus MGR's share with `mgr`; the largest cell and the least value.
  virtual PeakCell normalize(float keep, bool mgr) = 0;
  /// sum over headings of each cell in [u0, u1] x [v0, v1], row-major, into `out`.
  virtual void position_masses(int u0, int v0, int u1, int v1, std::span<double> out) const = 0;
  [[nodiscard]] virtual float value(int u, int v, int k) const = 0;
};

/// The engine of `backend` for a window of `config`'s size. Throws filter::FilterError as
/// DeviceFilter's constructor says.
[[nodiscard]] std::unique_ptr<DeviceFilter::Engine> make_engine(const filter::FilterConfig& config, Backend backend);

}  // namespace seqloc::gpu
