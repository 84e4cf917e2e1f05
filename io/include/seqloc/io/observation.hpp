#pragma once
// A BEV observation: what the vehicle sees around itself, as semantic classes in its own body
// frame, the input of the built-in matcher (docs/observation-format.md).
//
// The image is square with an odd side, 0.5 m cells; the camera sits at the centre of the middle
// cell; up is forward (row 0 is the farthest ahead), right is the vehicle's right. Each cell holds
// the three class codes of the region raster (areas, ways, nodes; conventions.md section 2) and a
// visibility flag: a cell that was not seen says nothing, a visible background cell says "nothing
// of that channel here".

#include <cstdint>
#include <filesystem>
#include <vector>

namespace seqloc::io {

struct Observation {
  int size = 0;                       ///< side in cells, odd
  std::vector<std::uint8_t> classes;  ///< size * size * 3, row-major, [areas, ways, nodes]
  std::vector<std::uint8_t> visible;  ///< size * size, 0 or 1

  Observation() = default;
  explicit Observation(int side);

  [[nodiscard]] std::size_t cells() const { return static_cast<std::size_t>(size) * static_cast<std::size_t>(size); }
  [[nodiscard]] std::size_t visible_cells() const;
};

/// Largest accepted side (a 256 m square): larger images are refused before decoding.
inline constexpr int kMaxObservationSize = 513;

/// Reads an observation PNG: 8-bit RGBA, R/G/B = class codes, alpha >= 128 = visible. Throws
/// DataError naming the file (and the first bad pixel) for a missing or corrupt file, another
/// pixel format, an even or too large side, or a code outside its channel's list.
[[nodiscard]] Observation read_observation(const std::filesystem::path& path);

/// Writes the PNG through a temporary file renamed into place. Throws IoError on I/O failure.
void write_observation(const std::filesystem::path& path, const Observation& observation);

}  // namespace seqloc::io
