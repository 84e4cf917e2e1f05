#pragma once
// How far to trust a pose, from the belief it came from (docs/route-format.md, "Uncertainty"):
// what a fusion stack (an EKF taking geometry_msgs/PoseWithCovariance) needs beside the estimate.
//
// With m(x) the belief's position marginal (summed over headings) and x_hat the estimate:
// - the position covariance about the estimate, sum m(x) (x - x_hat)(x - x_hat)^T, in m^2 along
//   the window's east and north (a belief centred off the estimate, or spread over two places,
//   shows as a larger covariance, never a smaller one);
// - the heading standard deviation about the estimate's heading, from the heading marginal, the
//   differences wrapped into [-180, 180);
// - the mass within 5 m of the estimate;
// - the second mode: the largest local maximum of the marginal farther than
//   kSecondModeMinDistanceM from the estimate with a valley between it and the estimate's peak
//   (the marginal below half the lower peak somewhere on the segment between them: two places,
//   not one ridge along a road), the mass within kNearM of it, and whether that share is at least
//   kSecondModeShare (multimodal: the covariance then spans both places, and a fusion stack
//   should not take the pose as one Gaussian).

#include "seqloc/core/ellipse.hpp"
#include "seqloc/filter/belief.hpp"
#include "seqloc/filter/types.hpp"

namespace seqloc::uncertainty {

using filter::BeliefVolume;
using filter::Pose;

struct PoseUncertainty {
  double cov_ee_m2 = 0, cov_en_m2 = 0, cov_nn_m2 = 0;  ///< position covariance, east/north, m^2
  double heading_sd_deg = 0;
  double mass_within_5m = 0;
  double second_mode_share = 0;       ///< the mass within 5 m of the second mode (0: none)
  double second_mode_distance_m = 0;  ///< its distance from the estimate
  bool multimodal = false;            ///< second_mode_share >= kSecondModeShare
};

inline constexpr double kNearM = 5.0;
inline constexpr double kSecondModeMinDistanceM = 10.0;
inline constexpr double kSecondModeShare = 0.10;

/// The uncertainty of `estimate` (window cells and grid heading) under `belief` (normalized or
/// not: it is normalized here). `threads` workers sum the marginals.
[[nodiscard]] PoseUncertainty pose_uncertainty(const BeliefVolume& belief, const Pose& estimate, int threads = 1);

/// The semi-axes (m) and the orientation (degrees clockwise from north of the major axis) of the
/// ellipse holding probability `p` of a Gaussian with this covariance: sqrt(chi2_2(p) lambda).
struct Ellipse {
  double major_m = 0, minor_m = 0, major_bearing_deg = 0;
};
[[nodiscard]] Ellipse covariance_ellipse(double cov_ee, double cov_en, double cov_nn, double p);

/// Whether an offset lies inside the covariance's ellipse of probability `p` (core/ellipse.hpp).
using core::inside_ellipse;

}  // namespace seqloc::uncertainty
