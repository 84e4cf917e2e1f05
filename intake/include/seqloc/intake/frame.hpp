#pragma once
// A backbone's pose likelihood volume as the filter takes it (conventions.md section 4): checked,
// raised to a power, normalized by its log-softmax over its own cells and stored heading-major,
// at the speed of memory (SIMD loops chosen at run time). The filter, its CUDA backend and the
// pipeline read frames in this form; the filter names these as its own (filter::PreparedFrame,
// filter::prepare_frame, ...).

#include <cstddef>
#include <string>

#include "seqloc/core/error.hpp"
#include "seqloc/core/units.hpp"
#include "seqloc/core/volume.hpp"
#include "seqloc/intake/aligned.hpp"

namespace seqloc::intake {

/// log(0) stands for this finite value inside the filter, so that no interpolation weight of 0
/// times -inf can produce a NaN; exp() of it is 0 in float and double.
inline constexpr float kLogZero = -1e30f;

/// A volume the intake cannot use (a wrong shape, NaN, +inf, a negative probability, no mass:
/// data) or a power that is not finite and > 0 (usage); the message says what and where.
class IntakeError : public Error {
 public:
  explicit IntakeError(const std::string& message, ErrorCategory category = ErrorCategory::data)
      : Error(category, message) {}
};

/// A frame volume checked, converted and normalized (log-softmax over its own H * W * N cells),
/// stored heading-major for sampling.
struct PreparedFrame {
  int height = 0, width = 0, bins = 0;
  double cell_m = core::kCellM;
  UninitializedAlignedVector<float> log_prob;  ///< [bin][v][u]; resize leaves new values unwritten
  double log_cells = 0;                        ///< log M
  double entropy = 0;                          ///< H_hat = -sum p log p / log M, in [0, 1]
  float max_log_prob = 0;                      ///< the largest normalized log-probability
  int argmax_v = 0, argmax_u = 0, argmax_bin = 0;
};

/// Checks and normalizes a volume (with `threads` workers), raised to `power` first (temper_frame's
/// power, in the same passes: p^power / sum p^power). Throws IntakeError for a wrong shape, NaN,
/// +inf, negative probabilities or a volume without mass (naming the first bad cell by its index in
/// (H, W, N) order), a log-probability that the power takes out of float's range, or a power that
/// is not finite and > 0; a -inf log-probability is a valid zero.
/// `window_headings`: the filter's heading bins, which the volume's must divide or be a multiple
/// of. Two passes over the volume as given and one write of the frame, in SIMD where the CPU has
/// it (intake_vector_lanes; docs/localize.md, "Speed").
[[nodiscard]] PreparedFrame prepare_frame(const core::FrameVolume& volume, int window_headings, int threads = 1,
                                          double power = 1.0);

/// The width, in floats, of the vectors prepare_frame's loops use here: 16 where the CPU has
/// AVX-512F, 8 where it has AVX2, FMA and F16C (log-probabilities; probabilities take the portable
/// sums), 1 (the portable loops) elsewhere and off x86-64; at most the limit below. Widths 16 and 8
/// give the same frame bit for bit; the portable loops agree with them within 1e-6.
[[nodiscard]] int intake_vector_lanes();

/// Limits intake_vector_lanes() to `lanes` (16, 8 or 1; 16 at start: the widest the CPU has), for
/// tests, benchmarks and machines whose clock drops under AVX-512. Returns the limit before; throws
/// IntakeError (usage) for another number. Applies to every thread.
int limit_intake_vector_lanes(int lanes);

/// Recomputes a frame's entropy, max_log_prob and argmax from its values as they stand (after
/// they were rounded, say), leaving the values untouched: what the filter reads of a frame then
/// describes the values it multiplies in.
void summarize_frame(PreparedFrame& frame, int threads = 1);

/// The log-softmax of the frame's values in place, with its entropy, max_log_prob and argmax:
/// for values changed after prepare_frame (a backbone calibration's blur and floor, say).
void normalize_frame(PreparedFrame& frame, int threads = 1);

/// temper_frame in place (the frame's storage is reused).
void temper_frame_in_place(PreparedFrame& frame, double power, int threads = 1);

/// The frame's volume raised to `power` and renormalized: p^k / sum p^k, i.e. its log-probabilities
/// divided by a temperature T = 1 / k. k > 1 sharpens (a backbone more confident than it should
/// be), k < 1 flattens; entropy and argmax are recomputed. Throws IntakeError unless k is finite
/// and > 0.
[[nodiscard]] PreparedFrame temper_frame(PreparedFrame frame, double power, int threads = 1);

/// The largest log-probability of the frame raised to `power` and renormalized (temper_frame's
/// max_log_prob, without writing the frame): a FrameWeighting's peak_log_prob at that power.
[[nodiscard]] float powered_peak_log_prob(const PreparedFrame& frame, double power, int threads = 1);

/// The smallest normal float: an exp under it counts zero in the filter's loops.
inline constexpr float kSmallestNormal = 1.17549435e-38f;

/// out = exp(scale * (x - shift)) where x > kLogZero, exactly 0 where x is kLogZero or -inf.
/// Eigen 3.4 evaluates select() one coefficient at a time, with scalar expf (a third of a step's
/// time): this keeps the exp in SIMD and blends the zeros in after. The exp is taken in an aligned
/// buffer a block at a time, so that which elements take Eigen's scalar path (a block's last
/// n % 8) depends on n alone, never on where out lies: results do not change with the heap or the
/// number of threads as long as callers cut the same n.
/// Values below the smallest normal float (1.2e-38 of the maximum) are 0 too: arithmetic on
/// subnormals takes a hundred cycles a value on x86, and a steep frame holds a band of them around
/// its support, which made every later pass over the frame and the belief up to seven times slower.
void exp_or_zero(const float* x, std::size_t n, float scale, float shift, float* out);

}  // namespace seqloc::intake
