#include "seqloc/io/observation.hpp"

#include <algorithm>
#include <fstream>
#include <iterator>

#include "seqloc/core/error.hpp"
#include "seqloc/core/files.hpp"
#include "seqloc/osm/classes.hpp"
#include "seqloc/raster/png_codec.hpp"

namespace seqloc::io {

Observation::Observation(int side)
    : size(side),
      classes(static_cast<std::size_t>(side) * static_cast<std::size_t>(side) * 3, 0),
      visible(static_cast<std::size_t>(side) * static_cast<std::size_t>(side), 0) {}

std::size_t Observation::visible_cells() const {
  return static_cast<std::size_t>(std::count(visible.begin(), visible.end(), std::uint8_t{1}));
}

Observation read_observation(const std::filesystem::path& path) {
  const std::string name = path.string();
  std::ifstream in(path, std::ios::binary);
  if (!in) throw DataError(name + ": cannot open the observation");
  const std::vector<std::uint8_t> blob{std::istreambuf_iterator<char>(in), std::istreambuf_iterator<char>()};
  raster::PngImage image;
  try {
    image = raster::decode_png(blob, name, kMaxObservationSize);  // huge sides refused from the header
  } catch (const raster::PngError& e) {
    throw DataError(e.what());
  }
  if (image.bit_depth != 8 || image.channels != 4) {
    std::ostringstream s;
    s << name << ": an observation is an 8-bit RGBA PNG; this one has " << image.channels << " channel(s) of "
      << image.bit_depth << " bits";
    throw DataError(s.str());
  }
  if (image.width != image.height || image.width % 2 == 0) {
    std::ostringstream s;
    s << name << ": an observation is square with an odd side (the camera in the middle cell); this one is "
      << image.width << " x " << image.height;
    throw DataError(s.str());
  }
  Observation obs(image.width);
  const std::size_t limits[3] = {osm::group_names(osm::Channel::areas).size(),
                                 osm::group_names(osm::Channel::ways).size(),
                                 osm::group_names(osm::Channel::nodes).size()};
  for (std::size_t i = 0; i < obs.cells(); ++i) {
    const std::uint8_t* px = image.pixels8.data() + 4 * i;
    for (int c = 0; c < 3; ++c) {
      if (px[c] > limits[c]) {
        std::ostringstream s;
        s << name << ": pixel (row " << i / static_cast<std::size_t>(obs.size) << ", column "
          << i % static_cast<std::size_t>(obs.size) << ") has " << osm::channel_name(static_cast<osm::Channel>(c))
          << " code " << int{px[c]} << "; the codes of that channel are 0.." << limits[c];
        throw DataError(s.str());
      }
      obs.classes[3 * i + static_cast<std::size_t>(c)] = px[c];
    }
    obs.visible[i] = px[3] >= 128 ? 1 : 0;
  }
  return obs;
}

void write_observation(const std::filesystem::path& path, const Observation& observation) {
  std::vector<std::uint8_t> rgba(observation.cells() * 4);
  for (std::size_t i = 0; i < observation.cells(); ++i) {
    std::copy_n(observation.classes.data() + 3 * i, 3, rgba.data() + 4 * i);
    rgba[4 * i + 3] = observation.visible[i] ? 255 : 0;
  }
  const auto png = raster::encode_png_rgba8(rgba, observation.size, observation.size);
  core::write_file(path, std::string(png.begin(), png.end()));
}

}  // namespace seqloc::io
