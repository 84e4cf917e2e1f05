#pragma once
// Plain inputs of the filter (conventions.md sections 1, 4 and 6). The filter is map-agnostic:
// positions are window cells (0.5 m, u east, v south, the cell's centre at integer (u, v)) and
// headings are grid headings, degrees clockwise from the window's north.

#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>

#include "seqloc/core/error.hpp"
#include "seqloc/core/units.hpp"
#include "seqloc/core/volume.hpp"

namespace seqloc::filter {

/// A frame volume or a configuration the filter cannot use; the message says what and why.
/// Data by default (a frame's values or shape); usage for a configuration (FilterConfig::validate).
class FilterError : public Error {
 public:
  explicit FilterError(const std::string& message, ErrorCategory category = ErrorCategory::data)
      : Error(category, message) {}
};

// The frame's volume, the motion and the half floats are the base layer's (core/volume.hpp).
using core::compose;
using core::float_to_half;
using core::floats_to_halves;
using core::FrameVolume;
using core::half_to_float;
using core::halves_to_floats;
using core::invert;
using core::Odometry;
using core::VolumeType;
using core::VolumeValues;
namespace detail {
using core::detail::float_to_half_portable;
using core::detail::half_to_float_portable;
}  // namespace detail

/// A pose in window coordinates.
struct Pose {
  double u = 0;            ///< window cells, east
  double v = 0;            ///< window cells, south
  double heading_deg = 0;  ///< grid heading, clockwise from window north, [0, 360)
};

/// Where a frame volume lies in the window: the window position (cells, may be fractional) of
/// the crop's centre, and the rotation of the crop's north from the window's north (degrees
/// clockwise; 0 for crops in region-grid coordinates, minus the meridian convergence for crops
/// north-up in the local tangent plane).
struct CropPose {
  double centre_u = 0;
  double centre_v = 0;
  double rotation_deg = 0;
};

}  // namespace seqloc::filter
