#pragma once
// Self-calibration's evidence from a frame and the predicted belief pooled onto a coarse grid:
// what SeqLocFilter feeds its PowerEstimator after each update, for backends that pool the belief
// themselves and judge it here (the CUDA backend, gpu/). docs/filter.md, "Self-calibration".

#include <cstddef>
#include <vector>

#include "seqloc/filter/belief.hpp"
#include "seqloc/filter/config.hpp"
#include "seqloc/filter/self_calibration.hpp"
#include "seqloc/filter/seqloc_filter.hpp"

namespace seqloc::filter {

/// The coarse grid self-calibration judges the predicted belief on, for a window of `config`'s
/// size: 2 x 2 cells and math::calibration_bins() heading bins in one (device_math.hpp pools them).
[[nodiscard]] BeliefVolume coarse_belief_for(const FilterConfig& config);

/// Adds a frame's own cells, binned by depth below its peak, to `cells` (a DepthHistogram::kCount
/// histogram): every calibration_bins()-th heading bin, each cell counting for that many.
void add_frame_cells(const PreparedFrame& frame, DepthHistogram& cells);

/// The predicted belief as the update pools it for self-calibration: each window heading bin that
/// math::pooled_bin() names summed over 2 x 2 cells (math::pool_2x2) into a `width` x `height`
/// slice at `slices` + k * width * height (window bin k of `headings`).
struct PooledBelief {
  const float* slices = nullptr;
  int width = 0, height = 0, headings = 0;
  [[nodiscard]] std::size_t slice_cells() const { return static_cast<std::size_t>(width) * height; }
};

/// The pooled belief of a window of `config`'s size, its slices at `slices` (coarse_belief_for's
/// cells).
[[nodiscard]] PooledBelief pooled_belief_for(const FilterConfig& config, const float* slices);

/// What coarse_evidence works in, per thread: kept from one frame to the next, so that a step
/// allocates none of its bins (each histogram is 256 kB).
struct JudgeScratch {
  struct Share {
    DepthHistogram in_crop;
    std::vector<float> blend, sample, depth, mass;
  };
  std::vector<Share> shares;
};

/// Sets `evidence` to that of `frame` at `crop` (window cells) against the coarse belief (of
/// coarse_belief_for's size) that `pooled` makes, its slices summed over headings as
/// math::pooled_weight says, with the frame's cells from add_frame_cells.
void coarse_evidence(const PooledBelief& pooled, const PreparedFrame& frame, const CropPose& crop,
                     const FilterConfig& config, const DepthHistogram& frame_cells, JudgeScratch& scratch,
                     CalibrationEvidence& evidence);

}  // namespace seqloc::filter
