#pragma once
// The shape of a frame's likelihood in the plane: a peak, or a ridge along the road. The paper's
// failure mode is the ridge (a rural frame pins the vehicle across the road but not along it);
// this measures it so the simulator can be checked against it (docs/simulate.md).

#include <vector>

#include "seqloc/filter/seqloc_filter.hpp"

namespace seqloc::pipeline {

struct VolumeShape {
  /// sqrt(l1 / l2) of the covariance of the structured mass (>= 1): 1 for a round peak, large
  /// for a ridge.
  double elongation = 1;
  /// Angle between the main axis and the heading given (degrees, 0-90): near 0 for a ridge along
  /// the direction of travel.
  double axis_to_heading_deg = 0;
  double major_sigma_m = 0, minor_sigma_m = 0;  ///< sqrt(l1), sqrt(l2)
};

/// The frame's probability per position, summed over headings: height x width, row-major (v, u).
[[nodiscard]] std::vector<double> position_marginal(const filter::PreparedFrame& frame);

/// The frame's position marginal placed in a width x height window as the filter places the frame
/// at `crop` (window cells): each volume cell's mass added at the window cell its centre falls in,
/// cells falling outside dropped. What `localize --beliefs` keeps of each frame (likelihoods.npy).
[[nodiscard]] std::vector<float> window_marginal(const filter::PreparedFrame& frame, const filter::CropPose& crop,
                                                 int width, int height);

/// The shape of the frame's position marginal (summed over headings). Only the mass above the
/// marginal's 10th percentile counts, so a uniform floor (a calibrated volume's "no information"
/// share) does not hide the structure. `heading_deg`: clockwise from the crop's north.
[[nodiscard]] VolumeShape volume_shape(const filter::PreparedFrame& frame, double heading_deg);

}  // namespace seqloc::pipeline
