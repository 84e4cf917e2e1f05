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

namespace seqloc::filter {

/// A frame volume or a configuration the filter cannot use; the message says what and why.
/// Data by default (a frame's values or shape); usage for a configuration (FilterConfig::validate).
class FilterError : public Error {
 public:
  explicit FilterError(const std::string& message, ErrorCategory category = ErrorCategory::data)
      : Error(category, message) {}
};

/// Motion between frames t-1 and t in the body frame of t-1 (conventions.md section 1):
/// forward and left in metres, yaw counter-clockwise positive (a left turn is positive), so the
/// heading (clockwise) at t is the heading at t-1 minus yaw_deg.
struct Odometry {
  double forward_m = 0;
  double left_m = 0;
  double yaw_deg = 0;
};

/// A pose in window coordinates.
struct Pose {
  double u = 0;            ///< window cells, east
  double v = 0;            ///< window cells, south
  double heading_deg = 0;  ///< grid heading, clockwise from window north, [0, 360)
};

enum class VolumeType { float32, float16 };
enum class VolumeValues { log_prob, prob };

/// A frame's pose likelihood volume as the backbone wrote it: shape (H, W, N), C order, bin j
/// holding heading j * 360 / N in the crop's own frame (conventions.md section 4). A view: the
/// data must outlive the call that takes it.
struct FrameVolume {
  const void* data = nullptr;
  VolumeType type = VolumeType::float32;
  VolumeValues values = VolumeValues::log_prob;
  int height = 0;
  int width = 0;
  int bins = 0;
  double cell_m = core::kCellM;  ///< the volume's cell size
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

/// 16-bit IEEE half to float (NumPy float16), exact.
float half_to_float(std::uint16_t h);

/// Float to the nearest 16-bit IEEE half, ties to even (as NumPy's astype(float16)): magnitudes
/// from 65520 up become infinity, below 2^-25 zero (keeping the sign); NaN stays NaN.
std::uint16_t float_to_half(float f);

/// half_to_float and float_to_half over whole arrays (`out` as long as the input), eight values
/// to an instruction where the CPU has F16C, which is asked at run time: a build for any x86-64
/// uses it where it is there. The results are those of the one-value functions, bit for bit but
/// for the payload bits of a NaN.
void halves_to_floats(std::span<const std::uint16_t> halves, std::span<float> out);
void floats_to_halves(std::span<const float> values, std::span<std::uint16_t> out);

namespace detail {
/// The same two conversions in plain integer code: what half_to_float and float_to_half run where
/// the CPU has no F16C instructions (a build without -march=x86-64-v3); tested against them.
float half_to_float_portable(std::uint16_t h);
std::uint16_t float_to_half_portable(float f);
}  // namespace detail

}  // namespace seqloc::filter
