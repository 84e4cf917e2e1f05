#include <random>

#include <cstring>

#include <png.h>
#include <zlib.h>

#include <gtest/gtest.h>

#include "seqloc/raster/png_codec.hpp"

namespace seqloc::raster {
namespace {

TEST(Png, RoundTripsRgb8AndGray16) {
  std::mt19937 rng(3);
  std::vector<std::uint8_t> rgb(64 * 48 * 3);
  for (auto& b : rgb) b = static_cast<std::uint8_t>(rng() % 40);
  const auto rgb_png = encode_png_rgb8(rgb, 64, 48);
  const auto rgb_back = decode_png(rgb_png, "rgb");
  EXPECT_EQ(rgb_back.channels, 3);
  EXPECT_EQ(rgb_back.bit_depth, 8);
  EXPECT_EQ(rgb_back.pixels8, rgb);

  std::vector<std::uint16_t> grey(64 * 48);
  for (auto& g : grey) g = static_cast<std::uint16_t>(rng() % 65536);
  const auto grey_png = encode_png_gray16(grey, 64, 48);
  const auto grey_back = decode_png(grey_png, "grey");
  EXPECT_EQ(grey_back.channels, 1);
  EXPECT_EQ(grey_back.bit_depth, 16);
  EXPECT_EQ(grey_back.pixels16, grey);
}

TEST(Png, CorruptDataIsAnErrorNamingTheBlob) {
  std::vector<std::uint16_t> grey(32 * 32, 1234);
  auto png = encode_png_gray16(grey, 32, 32);
  EXPECT_THROW((void)decode_png(std::vector<std::uint8_t>{1, 2, 3}, "tile (1, 2)"), PngError);
  auto truncated = png;
  truncated.resize(png.size() / 2);
  try {
    (void)decode_png(truncated, "tile (1, 2)");
    FAIL();
  } catch (const PngError& e) {
    EXPECT_NE(std::string(e.what()).find("tile (1, 2)"), std::string::npos);
  }
  auto flipped = png;
  for (std::size_t i = 40; i < flipped.size() - 12; i += 7) flipped[i] ^= 0x5a;
  EXPECT_THROW((void)decode_png(flipped, "tile"), PngError);
}

}  // namespace
}  // namespace seqloc::raster

namespace seqloc::raster {
namespace {

// A PNG written by libpng itself (its adaptive filter choice uses all five filter types), plain
// and interlaced: the fast path must decode the first, libpng the second, both to the pixels.
std::vector<std::uint8_t> libpng_encode(const void* pixels, int w, int h, int depth, int color, bool interlaced) {
  std::vector<std::uint8_t> out;
  png_structp png = png_create_write_struct(PNG_LIBPNG_VER_STRING, nullptr, nullptr, nullptr);
  png_infop info = png_create_info_struct(png);
  png_set_write_fn(
      png, &out,
      [](png_structp p, png_bytep data, png_size_t n) {
        auto* v = static_cast<std::vector<std::uint8_t>*>(png_get_io_ptr(p));
        v->insert(v->end(), data, data + n);
      },
      nullptr);
  png_set_filter(png, PNG_FILTER_TYPE_BASE, PNG_ALL_FILTERS);
  png_set_IHDR(png, info, static_cast<png_uint_32>(w), static_cast<png_uint_32>(h), depth, color,
               interlaced ? PNG_INTERLACE_ADAM7 : PNG_INTERLACE_NONE, PNG_COMPRESSION_TYPE_BASE, PNG_FILTER_TYPE_BASE);
  const int row_bytes = w * (color == PNG_COLOR_TYPE_RGB ? 3 : 1) * depth / 8;
  std::vector<png_bytep> rows(static_cast<std::size_t>(h));
  for (int r = 0; r < h; ++r) {
    rows[static_cast<std::size_t>(r)] = const_cast<png_bytep>(static_cast<const std::uint8_t*>(pixels) + r * row_bytes);
  }
  png_set_rows(png, info, rows.data());
  // Small IDAT chunks, so that the image data spans many of them.
  png_set_compression_buffer_size(png, 1024);
  png_write_png(png, info, depth == 16 ? PNG_TRANSFORM_SWAP_ENDIAN : PNG_TRANSFORM_IDENTITY, nullptr);
  png_destroy_write_struct(&png, &info);
  return out;
}

// The IHDR of `png` rewritten to claim another size (and interlacing), with a valid CRC.
std::vector<std::uint8_t> with_header(std::vector<std::uint8_t> png, std::uint32_t width, std::uint32_t height,
                                      bool interlaced) {
  auto put = [&](std::size_t at, std::uint32_t v) {
    for (int i = 0; i < 4; ++i) png[at + static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(v >> (24 - 8 * i));
  };
  put(16, width);
  put(20, height);
  png[28] = interlaced ? 1 : 0;
  put(29, static_cast<std::uint32_t>(crc32(0, png.data() + 12, 17)));
  return png;
}

TEST(Png, AbsurdSidesAreRefusedFromTheHeader) {
  const std::vector<std::uint8_t> rgb(5 * 3 * 3, 7);
  const auto png = encode_png_rgb8(rgb, 5, 3);
  EXPECT_EQ(decode_png(png, "ok", 5).width, 5);
  for (const bool interlaced : {false, true}) {  // our fast path, then libpng's
    SCOPED_TRACE(interlaced ? "libpng" : "fast path");
    try {
      // 100,000 x 100,000: within libpng's own limits, 30 GB of RGB.
      (void)decode_png(with_header(png, 100000, 100000, interlaced), "huge.png");
      FAIL() << "a 100,000 x 100,000 image was not refused";
    } catch (const PngError& e) {
      EXPECT_NE(std::string(e.what()).find("huge.png"), std::string::npos) << e.what();
      EXPECT_NE(std::string(e.what()).find("largest accepted side"), std::string::npos) << e.what();
    }
    // The caller's own limit: a 600-pixel-wide "tile" where 512 are expected.
    EXPECT_THROW((void)decode_png(with_header(png, 600, 3, interlaced), "tile", 512), PngError);
  }
  EXPECT_THROW((void)decode_png(png, "small limit", 4), PngError);
}

TEST(Png, DecodesPngsFromOtherWriters) {
  std::mt19937 rng(9);
  const int w = 97, h = 61;
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(w * h * 3));
  // Smooth gradients plus noise, so that libpng picks different filters per row.
  for (int i = 0; i < w * h * 3; ++i) rgb[static_cast<std::size_t>(i)] = static_cast<std::uint8_t>(i / 7 + rng() % 9);
  for (bool interlaced : {false, true}) {
    const auto png = libpng_encode(rgb.data(), w, h, 8, PNG_COLOR_TYPE_RGB, interlaced);
    const auto image = decode_png(png, "libpng");
    EXPECT_EQ(image.width, w);
    EXPECT_EQ(image.channels, 3);
    EXPECT_EQ(image.pixels8, rgb) << (interlaced ? "interlaced" : "plain");
  }
  // 16-bit grey with libpng's choice of filters, over many IDAT chunks.
  std::vector<std::uint16_t> grey(static_cast<std::size_t>(w * h));
  for (int i = 0; i < w * h; ++i) grey[static_cast<std::size_t>(i)] = static_cast<std::uint16_t>(i * 37 + rng() % 300);
  const auto png = libpng_encode(grey.data(), w, h, 16, PNG_COLOR_TYPE_GRAY, false);
  int idat = 0;
  for (std::size_t i = 0; i + 4 <= png.size(); ++i) idat += std::memcmp(png.data() + i, "IDAT", 4) == 0;
  EXPECT_GT(idat, 2) << "the fixture must span several IDAT chunks";
  const auto image = decode_png(png, "libpng16");
  EXPECT_EQ(image.bit_depth, 16);
  EXPECT_EQ(image.pixels16, grey);
}

}  // namespace
}  // namespace seqloc::raster
