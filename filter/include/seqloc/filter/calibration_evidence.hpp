#pragma once
// Self-calibration's evidence from a frame and the predicted belief pooled onto a coarse grid:
// what SeqLocFilter feeds its PowerEstimator after each update, for backends that pool the belief
// themselves and judge it here (the CUDA backend, gpu/). docs/filter.md, "Self-calibration".

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

/// The evidence of `frame` at `crop` (window cells) against `coarse`, the predicted belief pooled
/// as math::pool_2x2 and math::pooled_weight say, with the frame's cells from add_frame_cells.
[[nodiscard]] CalibrationEvidence coarse_evidence(const BeliefVolume& coarse, const PreparedFrame& frame,
                                                  const CropPose& crop, const FilterConfig& config,
                                                  const DepthHistogram& frame_cells);

}  // namespace seqloc::filter
