#pragma once
// Exact Euclidean distance transform (conventions.md section 2, road distance).
//
// The squared distance in cells from each cell centre to the nearest marked cell centre, computed
// separably: a column pass gives the exact 1-D distance to the nearest mark in the column, then a
// row pass takes, for each cell, the lower envelope of the parabolas (u - q)^2 + g(q) over the row
// (Felzenszwalb and Huttenlocher, "Distance Transforms of Sampled Functions", 2012). Both passes
// are exact in integers, so the distance in metres is exact before the final quantization.

#include <cmath>
#include <cstdint>
#include <span>
#include <vector>

namespace seqloc::raster {

/// Marks no cell within reach: the squared distance of a cell with no mark in its window.
inline constexpr std::uint32_t kNoMark = 0xFFFFFFFFu;

/// Scratch buffers of the transform (one per thread, reused across tiles).
struct DistanceScratch {
  std::vector<std::uint16_t> column;  ///< vertical distances (cells) of the output rows
  std::vector<std::uint16_t> up;      ///< running distance to the last mark above, per column
  std::vector<std::int32_t> hull_q;
  std::vector<double> hull_z;
};

/// Squared distances (in cells^2) for the cells of the output rectangle
/// [out_u0, out_u0 + out_w) x [out_v0, out_v0 + out_h) of a width x height mask (non-zero = mark),
/// taking every mark of the whole mask into account. Row-major, out_w * out_h values; kNoMark
/// where the mask has no mark at all in the relevant rows.
///
/// With `reach` > 0 only distances up to `reach` cells are wanted: any cell farther from every
/// mark may get kNoMark instead of its distance (marks more than `reach` rows away from a cell's
/// column are skipped), which is exact once the result is clamped at `reach`.
void squared_distance(std::span<const std::uint8_t> mask, int width, int height, int out_u0, int out_v0, int out_w,
                      int out_h, DistanceScratch& scratch, std::vector<std::uint32_t>& out, int reach = 0);

/// Reference implementation for tests: brute force over all marks, in double precision metres
/// (cell size `cell_m`), for the whole mask; a large value where there is no mark.
[[nodiscard]] std::vector<double> brute_force_distance_m(std::span<const std::uint8_t> mask, int width, int height,
                                                         double cell_m);

/// Road distance in centimetres as stored (UInt16): round(distance_m * 100), clamped.
[[nodiscard]] inline std::uint16_t quantize_distance_cm(std::uint32_t squared_cells, double cell_m,
                                                        std::uint16_t max_cm) {
  if (squared_cells == kNoMark) return max_cm;
  const double cm = std::sqrt(static_cast<double>(squared_cells)) * cell_m * 100.0;
  if (cm >= max_cm) return max_cm;
  // cm >= 0 here, where adding 0.5 and truncating rounds half up (no libm call per cell).
  return static_cast<std::uint16_t>(cm + 0.5);  // NOLINT(bugprone-incorrect-roundings)
}

/// quantize_distance_cm() as a table over the squared distances below the clamp (the same values,
/// without a square root per cell).
class DistanceQuantizer {
 public:
  DistanceQuantizer(double cell_m, std::uint16_t max_cm);
  [[nodiscard]] std::uint16_t operator()(std::uint32_t squared_cells) const {
    return squared_cells < table_.size() ? table_[squared_cells] : max_cm_;
  }
  /// The clamp in cells, rounded up: the `reach` to pass to squared_distance().
  [[nodiscard]] int reach_cells() const { return reach_; }

 private:
  std::vector<std::uint16_t> table_;
  std::uint16_t max_cm_;
  int reach_;
};

}  // namespace seqloc::raster
