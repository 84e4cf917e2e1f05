#pragma once
// Pieces of the filter shared by the online filter and the offline baseline.

#include <algorithm>
#include <cstddef>
#include <vector>

#include <Eigen/Core>

#include "seqloc/filter/belief.hpp"
#include "seqloc/filter/device_math.hpp"
#include "seqloc/filter/self_calibration.hpp"
#include "seqloc/filter/seqloc_filter.hpp"

namespace seqloc::filter::detail {

/// A float buffer as an Eigen array, in place (the filter's loops work on these).
using ArrayMap = Eigen::Map<Eigen::ArrayXf>;
using ConstArrayMap = Eigen::Map<const Eigen::ArrayXf>;

/// out = exp(scale * (x - shift)), 0 for zero cells and subnormal results (intake/frame.hpp).
using intake::exp_or_zero;

/// dst(u, v) = src sampled bilinearly at (u + ou, v + ov) for a dw x dh destination from a sw x sh
/// source; `fill` where that point lies outside the source [0, sw - 1] x [0, sh - 1]. At the
/// last column or row the missing neighbour has weight 0 and is read clamped. A NaN neighbour
/// makes the result NaN even at weight 0.
void translate(const float* src, int sw, int sh, float* dst, int dw, int dh, double ou, double ov, float fill);

/// Samples a heading-major frame array (`values`: bins x vh x vw, e.g. log-probabilities, or
/// tempered probabilities) at every window cell for one window heading, into `out` (width x
/// height): linear in heading, bilinear in space; `fill` where the cell's centre is outside the
/// crop. `blend_buffer` is scratch space.
void sample_slice(const float* values, int bins, int vh, int vw, double cell_m, const CropPose& crop,
                  double heading_deg, int width, int height, float fill, std::vector<float>& blend_buffer, float* out);

/// Backward warp of a whole volume through the odometry (see seqloc_filter.hpp), interpolating
/// the stored values linearly; cells whose source lies outside the window get `fill`.
void warp_volume(const BeliefVolume& in, BeliefVolume& out, const Odometry& odometry, float fill, int threads);

/// Window displacement (cells, u east / v south) of the odometry for a heading (clockwise from
/// north): forward is (sin h, cos h) east/north, left is (-cos h, sin h).
void displacement_cells(const Odometry& odometry, double heading_deg, double& du, double& dv);

/// Self-calibration's coarse grid (device_math.hpp).
using math::calibration_bins;
using math::pooled_bin;

/// The coarse belief from `pooled` ([bin][v][u] at the coarse grid's cells, one slice per window
/// bin, filled for the bins pooled_bin() names): coarse bin j is centred on window bin j b and
/// sums the named bins among j b - b/2 .. j b + b/2 (circular), each standing for itself and its
/// neighbours, those at the ends for half as many: weights 1, 2, 1 for b = 4, 1, 1 for b = 2.
void pool_headings(const float* pooled, int headings, BeliefVolume& coarse, int threads);

/// Self-calibration's evidence of a frame against a belief on another grid: the belief's mass
/// binned by the frame's depth below its peak at each cell (the frame's log-probabilities sampled
/// at the cell's centre, `frame_cell_m` being the frame's cell size in the belief's cells times
/// 0.5 m, `crop` the crop in the belief's cells), its mass outside the crop, and its cells in all
/// and outside the crop, each counted as `cells_per_cell` window cells. The same sums for any
/// number of threads.
void judge_frame(const BeliefVolume& belief, const PreparedFrame& frame, double frame_cell_m, const CropPose& crop,
                 double cells_per_cell, int threads, CalibrationEvidence& evidence);

}  // namespace seqloc::filter::detail
