#pragma once
// PNG encoding and decoding in memory: 8-bit RGB for the class raster, 16-bit grey for the road
// distance (the two tile encodings of the region cache), 8-bit RGBA for BEV observations.

#include <cstdint>
#include <span>
#include <stdexcept>
#include <string>
#include <vector>

#include "seqloc/core/error.hpp"

namespace seqloc::raster {

/// Corrupt or unsupported PNG data.
class PngError : public Error {
 public:
  explicit PngError(const std::string& message) : Error(ErrorCategory::data, message) {}
};

struct PngImage {
  int width = 0;
  int height = 0;
  int channels = 0;    ///< 1 (grey), 3 (RGB) or 4 (RGBA)
  int bit_depth = 0;   ///< 8 or 16
  std::vector<std::uint8_t> pixels8;    ///< row-major, interleaved, when bit_depth == 8
  std::vector<std::uint16_t> pixels16;  ///< row-major, when bit_depth == 16 (native byte order)
};

/// Written with libdeflate (level 1) and a fixed filter per encoding; any PNG decodes (libpng
/// handles what the fast path does not: palettes, other depths, interlacing).
[[nodiscard]] std::vector<std::uint8_t> encode_png_rgb8(std::span<const std::uint8_t> rgb, int width, int height);
[[nodiscard]] std::vector<std::uint8_t> encode_png_rgba8(std::span<const std::uint8_t> rgba, int width, int height);
[[nodiscard]] std::vector<std::uint8_t> encode_png_gray16(std::span<const std::uint16_t> values, int width, int height);
/// Largest side decode_png accepts unless told otherwise.
inline constexpr int kMaxPngSide = 8192;

/// Throws PngError (with `what` naming the blob's origin) on corrupt data, and on an image wider
/// or taller than `max_side`, refused from its header before any pixel buffer is allocated.
[[nodiscard]] PngImage decode_png(std::span<const std::uint8_t> blob, const std::string& what,
                                  int max_side = kMaxPngSide);

}  // namespace seqloc::raster
