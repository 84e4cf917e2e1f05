// Fuzz target: decoding of tile blobs (raster/png_codec.hpp), both paths: our fast decoder for
// the PNGs the cache writes and libpng for everything else. The first byte picks the side limit
// (a cache tile's 512 or the general one), the rest is the blob.
#include <cstdint>
#include <span>

#include "seqloc/raster/grid.hpp"
#include "seqloc/raster/png_codec.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size == 0) return 0;
  const int max_side = (data[0] & 1) ? seqloc::raster::kTilePx : seqloc::raster::kMaxPngSide;
  try {
    const auto image = seqloc::raster::decode_png(std::span(data + 1, size - 1), "fuzz", max_side);
    const std::size_t samples = static_cast<std::size_t>(image.width) * static_cast<std::size_t>(image.height) *
                                static_cast<std::size_t>(image.channels);
    const bool consistent = image.width > 0 && image.height > 0 && image.width <= max_side &&
                            image.height <= max_side &&
                            (image.bit_depth == 8 ? image.pixels8.size() == samples
                                                  : image.bit_depth == 16 && image.pixels16.size() == samples);
    if (!consistent) std::abort();  // a decoded image has exactly its pixels
  } catch (const seqloc::raster::PngError&) {
  }
  return 0;
}
