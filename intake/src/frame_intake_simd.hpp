#pragma once
// The frame intake's inner loops in SIMD (AVX-512F, or AVX2 with FMA and F16C), for CPUs that
// have them: the values converted from float16 in registers, checked, raised to the power, their
// online softmax summed with a polynomial exp, and written heading-major through 8 x 8 transposes,
// each value read from the volume as given without an intermediate row. frame_intake.cpp asks
// intake_simd_available() and falls back to its portable loops where it says no.

#include <cstddef>
#include <cstdint>

#include "seqloc/core/volume.hpp"

namespace seqloc::intake::detail {

/// The width of the vectors the loops below use (floats): 16 where the CPU has AVX-512F, 8 where it
/// has AVX2, FMA and F16C, at most the cap (cap_intake_lanes); 1 (the portable loops) otherwise and
/// off x86-64. Both widths give the same values, bit for bit.
[[nodiscard]] int intake_lanes();
/// Caps intake_lanes() at `lanes` (16 by default); returns the cap before.
int cap_intake_lanes(int lanes);
/// Whether the loops below run here (intake_lanes() > 1).
[[nodiscard]] inline bool intake_simd_available() { return intake_lanes() > 1; }

/// A view of a frame's values as given: element (v, u, j) at data[(v * width + u) * cell_stride + j],
/// float16 or float32 log-probabilities (or one row of them, height 1).
struct IntakeSource {
  const void* data = nullptr;
  core::VolumeType type = core::VolumeType::float32;
  int height = 0, width = 0;
  std::size_t cell_stride = 0;
};

/// The online softmax of bins j0 .. j1 (log-probabilities raised to `power`; values at or below
/// kLogZero, -inf among them, count zero): per bin the largest value `max`, and `sum` of e and `ex`
/// of e x with e = exp(x - max) (e under the smallest normal float counts zero), a row at a time in
/// float and across rows in double, rescaled whenever max grows. The sums of a bin are the same
/// whichever bins share the call. Returns false, with the sums unfinished, where a value is NaN or
/// +inf, or leaves float's range when raised to `power` (found in the sums, not value by value).
[[nodiscard]] bool intake_sums_simd(const IntakeSource& source, int j0, int j1, float power, float* max, double* sum,
                                    double* ex);

/// Row v of bins j0 .. j1 written heading-major as x - shift, x the value raised to `power`, values
/// at or below kLogZero as kLogZero: bin j0 + b of cell u at out[b * slice + u]. Needs
/// (j1 - j0) % 8 == 0 and width % 16 == 0. Returns the row's largest x.
float intake_write_row_simd(const IntakeSource& source, int v, int j0, int j1, float power, float shift, float* out,
                            std::size_t slice);

}  // namespace seqloc::intake::detail
