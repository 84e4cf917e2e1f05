#include <random>

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
