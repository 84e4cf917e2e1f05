#pragma once
// What a backbone hands the localizer for each frame, as every stage reads it (conventions.md
// sections 1 and 4): the frame's pose likelihood volume, the motion since the frame before, and
// the 16-bit floats a volume is often stored in. Plain values of the base layer, so that the
// readers of route folders (io) need not depend on the filter that consumes them.

#include <cstdint>
#include <span>
#include <vector>

#include "seqloc/core/units.hpp"

namespace seqloc::core {

/// Motion between frames t-1 and t in the body frame of t-1 (conventions.md section 1):
/// forward and left in metres, yaw counter-clockwise positive (a left turn is positive), so the
/// heading (clockwise) at t is the heading at t-1 minus yaw_deg.
struct Odometry {
  double forward_m = 0;
  double left_m = 0;
  double yaw_deg = 0;
};

/// The relative motion from a pose to a later one, composed from the increments in between
/// (each in the body frame of its start), expressed in the body frame of the first pose.
[[nodiscard]] Odometry compose(const std::vector<Odometry>& increments);
/// The motion that undoes `motion` (expressed in the body frame of its end).
[[nodiscard]] Odometry invert(const Odometry& motion);

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
  double cell_m = kCellM;  ///< the volume's cell size
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

}  // namespace seqloc::core
