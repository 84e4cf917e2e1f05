#pragma once
// The one resolution of every raster seqloc makes and reads (conventions.md section 2): the
// region rasters, the belief window and the built-in matcher's volumes all have 0.5 m cells.

namespace seqloc::core {

/// Side of a raster cell in metres (2 px/m).
inline constexpr double kCellM = 0.5;

}  // namespace seqloc::core
