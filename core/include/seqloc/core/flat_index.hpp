#pragma once
// The offset of a cell in a row-major raster.

#include <cstddef>

namespace seqloc::core {

/// Offset of (row, col) in a row-major table `width` wide, computed in size_t: the product of
/// two ints is not formed in int (rows, columns and width are all >= 0).
inline std::size_t flat(int row, int col, int width) {
  return static_cast<std::size_t>(row) * static_cast<std::size_t>(width) + static_cast<std::size_t>(col);
}

}  // namespace seqloc::core
