#pragma once
// Pieces of the filter shared by the online filter, the bank and the smoother.

#include <algorithm>
#include <cstddef>
#include <vector>

#include <Eigen/Core>

#include "seqloc/filter/belief.hpp"
#include "seqloc/filter/calibration_evidence.hpp"
#include "seqloc/filter/device_math.hpp"
#include "seqloc/filter/resample.hpp"
#include "seqloc/filter/self_calibration.hpp"
#include "seqloc/filter/seqloc_filter.hpp"

namespace seqloc::filter::detail {

/// A float buffer as an Eigen array, in place (the filter's loops work on these).
using ArrayMap = Eigen::Map<Eigen::ArrayXf>;
using ConstArrayMap = Eigen::Map<const Eigen::ArrayXf>;

/// out = exp(scale * (x - shift)), 0 for zero cells and subnormal results (intake/frame.hpp).
using intake::exp_or_zero;

/// The resampling of probabilities (resample.hpp), as the filter's loops name it.
using filter::displacement_cells;
using filter::sample_slice;
using filter::translate;
using filter::warp_volume;

/// Self-calibration's coarse grid (device_math.hpp).
using math::calibration_bins;
using math::pooled_bin;

/// Coarse bin j of the belief `pooled` makes, into `out` (one coarse slice): coarse bin j is centred
/// on window bin j b and sums the named bins among j b - b/2 .. j b + b/2 (circular), each standing
/// for itself and its neighbours, those at the ends for half as many: weights 1, 2, 1 for b = 4,
/// 1, 1 for b = 2.
void pool_heading(const PooledBelief& pooled, int j, float* out);

/// Self-calibration's evidence of a frame against the coarse belief `pooled` makes (each of its
/// slices made by pool_heading() as it is judged): the belief's mass binned by the frame's depth
/// below its peak at each cell (the frame's log-probabilities sampled at the cell's centre,
/// `frame_cell_m` being the frame's cell size in coarse cells times 0.5 m, `crop` the crop in
/// coarse cells), its mass outside the crop, and its cells in all and outside the crop, each
/// counted as `cells_per_cell` window cells. The same sums for any number of threads.
void judge_frame(const PooledBelief& pooled, const PreparedFrame& frame, double frame_cell_m, const CropPose& crop,
                 double cells_per_cell, int threads, JudgeScratch& scratch, CalibrationEvidence& evidence);

}  // namespace seqloc::filter::detail
