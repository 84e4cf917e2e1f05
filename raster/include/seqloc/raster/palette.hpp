#pragma once
// The colours of the class raster (conventions.md section 3) for pictures and map tiles, in the
// spirit of OpenStreetMap's carto style: areas first, then ways, then nodes drawn on top.

#include <cstdint>
#include <span>
#include <vector>

namespace seqloc::raster {

/// RGB bytes (row-major, 3 per cell) of class cells given as the cache's 3-channel codes
/// (area, way, node per cell): background white; buildings brown-grey, grass light green, forest
/// green, water blue; roads dark grey, paths brown, cycleways blue; trees green, other nodes orange.
[[nodiscard]] std::vector<std::uint8_t> class_colours(std::span<const std::uint8_t> classes_rgb);

}  // namespace seqloc::raster
