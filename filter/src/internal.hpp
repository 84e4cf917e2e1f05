#pragma once
// Pieces of the filter shared by the online filter and the offline baseline.

#include <vector>

#include "seqloc/filter/belief.hpp"
#include "seqloc/filter/seqloc_filter.hpp"

namespace seqloc::filter::detail {

/// The frame's log-probability at every cell of the window for one window heading, into `out`
/// (width x height); log(1/M) outside the crop. `blend_buffer` is scratch space.
void sample_frame_slice(const PreparedFrame& frame, const CropPose& crop, double heading_deg, int width, int height,
                        std::vector<float>& blend_buffer, float* out);

/// Backward warp of a whole volume through the odometry (see seqloc_filter.hpp); cells whose
/// source lies outside the window get `fill`.
void warp_volume(const BeliefVolume& in, BeliefVolume& out, const Odometry& odometry, float fill, int threads);

/// Window displacement (cells, u east / v south) of the odometry for a heading (clockwise from
/// north): forward is (sin h, cos h) east/north, left is (-cos h, sin h).
void displacement_cells(const Odometry& odometry, double heading_deg, double& du, double& dv);

}  // namespace seqloc::filter::detail
