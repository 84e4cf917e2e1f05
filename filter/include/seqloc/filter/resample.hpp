#pragma once
// The filter's resampling of probabilities (seqloc_filter.hpp's interpolation): a slice translated
// by a sub-cell offset, a frame sampled into the window at a crop, a belief warped backwards
// through odometry. The filter, its bank and the offline baseline (offline/) place frames with them.

#include <vector>

#include "seqloc/filter/belief.hpp"
#include "seqloc/filter/types.hpp"

namespace seqloc::filter {

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

}  // namespace seqloc::filter
