#include "seqloc/raster/palette.hpp"

#include <algorithm>
#include <array>

namespace seqloc::raster {
namespace {

using Rgb = std::array<std::uint8_t, 3>;

Rgb area_colour(int code) {
  static constexpr Rgb kColours[] = {{255, 255, 255}, {196, 182, 171}, {238, 238, 238}, {223, 252, 226},
                                     {205, 235, 176}, {200, 250, 204}, {173, 209, 158}, {170, 211, 223}};
  return kColours[std::clamp(code, 0, 7)];
}

Rgb way_colour(int code) {
  static constexpr Rgb kColours[] = {{0, 0, 0},       {140, 120, 100}, {150, 150, 150}, {110, 160, 90},
                                     {160, 160, 160}, {140, 140, 140}, {60, 60, 230},   {200, 120, 80},
                                     {70, 70, 70},    {200, 60, 200},  {90, 140, 70}};
  return kColours[std::clamp(code, 0, 10)];
}

}  // namespace

std::vector<std::uint8_t> class_colours(std::span<const std::uint8_t> classes_rgb) {
  std::vector<std::uint8_t> out(classes_rgb.size() / 3 * 3);
  for (std::size_t i = 0; i < out.size(); i += 3) {
    const std::uint8_t* c = classes_rgb.data() + i;
    Rgb colour = area_colour(c[0]);
    if (c[1]) colour = way_colour(c[1]);
    if (c[2]) colour = c[2] == 1 ? Rgb{40, 130, 40} : Rgb{200, 80, 40};  // trees green, other nodes orange
    std::copy(colour.begin(), colour.end(), out.begin() + static_cast<std::ptrdiff_t>(i));
  }
  return out;
}

}  // namespace seqloc::raster
