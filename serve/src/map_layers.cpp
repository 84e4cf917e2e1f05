#include "seqloc/serve/map_layers.hpp"

#include <algorithm>
#include <array>
#include <bit>
#include <cmath>
#include <cstring>

#include "seqloc/core/road_prior.hpp"
#include "seqloc/raster/palette.hpp"
#include "seqloc/raster/png_codec.hpp"

namespace seqloc::serve {

static_assert(std::endian::native == std::endian::little, ".npy output is written as little-endian");

const char* layer_name(MapLayer layer) {
  switch (layer) {
    case MapLayer::classes: return "classes";
    case MapLayer::road_distance: return "road_distance";
    case MapLayer::road_prior: return "road_prior";
  }
  return "?";
}

std::optional<MapLayer> parse_layer(std::string_view name) {
  for (MapLayer layer : kAllLayers) {
    if (name == layer_name(layer)) return layer;
  }
  return std::nullopt;
}

std::vector<MapLayer> parse_layer_list(std::string_view names) {
  std::vector<MapLayer> layers;
  std::size_t start = 0;
  while (start <= names.size()) {
    const std::size_t comma = std::min(names.find(',', start), names.size());
    const std::string_view name = names.substr(start, comma - start);
    const auto layer = parse_layer(name);
    if (!layer) {
      throw RequestError(RequestError::Kind::bad_request,
                         "layers: unknown layer '" + std::string(name) + "' (known: classes, road_distance, road_prior)");
    }
    if (std::find(layers.begin(), layers.end(), *layer) != layers.end()) {
      throw RequestError(RequestError::Kind::bad_request, "layers: '" + std::string(name) + "' is listed twice");
    }
    layers.push_back(*layer);
    start = comma + 1;
  }
  return layers;
}

bool MapBlock::all_uint8() const {
  return std::all_of(bands.begin(), bands.end(), [](const Band& b) { return b.is_uint8; });
}

namespace {

std::size_t cells(int width, int height) { return static_cast<std::size_t>(width) * static_cast<std::size_t>(height); }

std::int64_t count_outside(const raster::RegionGrid& grid, std::int64_t u0, std::int64_t v0, int width, int height) {
  const std::int64_t u_in = std::max<std::int64_t>(0, std::min(u0 + width, grid.width_px()) - std::max<std::int64_t>(u0, 0));
  const std::int64_t v_in = std::max<std::int64_t>(0, std::min(v0 + height, grid.height_px()) - std::max<std::int64_t>(v0, 0));
  return static_cast<std::int64_t>(width) * height - u_in * v_in;
}

}  // namespace

void LayerOptions::validate() const {
  if (!(prior_sigma_m > 0) || !std::isfinite(prior_sigma_m)) {
    throw RequestError(RequestError::Kind::bad_request, "layer options: prior_sigma_m = " + std::to_string(prior_sigma_m) + ": must be finite and > 0");
  }
}

MapBlock describe_block(const raster::CacheReader& cache, std::int64_t u0, std::int64_t v0, int width, int height,
                        const std::vector<MapLayer>& layers) {
  const auto& grid = cache.grid();
  MapBlock block;
  block.width = width;
  block.height = height;
  block.west_m = grid.min_x() + static_cast<double>(u0) * raster::kCellM;
  block.north_m = grid.max_y() - static_cast<double>(v0) * raster::kCellM;
  block.layers = layers;
  block.outside_cells = count_outside(grid, u0, v0, width, height);
  for (MapLayer layer : layers) {
    if (layer == MapLayer::classes) {
      for (const char* channel : {"classes.areas", "classes.ways", "classes.nodes"}) block.bands.push_back({channel, true, {}, {}});
    } else {
      block.bands.push_back({layer_name(layer), false, {}, {}});
    }
  }
  return block;
}

MapBlock read_block(raster::CacheReader& cache, std::int64_t u0, std::int64_t v0, int width, int height,
                    const std::vector<MapLayer>& layers, const LayerOptions& options, bool fill_outside) {
  MapBlock block = describe_block(cache, u0, v0, width, height, layers);
  const std::size_t n = cells(width, height);

  // Road distances in metres (raster's conversion), read once for both layers made from them.
  std::vector<float> metres;
  const bool wants_distance = std::any_of(layers.begin(), layers.end(), [](MapLayer l) { return l != MapLayer::classes; });
  if (wants_distance) cache.read_road_distance_m(u0, v0, width, height, metres, fill_outside);

  auto band = block.bands.begin();  // in the order describe_block named them
  for (MapLayer layer : layers) {
    switch (layer) {
      case MapLayer::classes: {
        std::vector<std::uint8_t> rgb;
        cache.read_classes(u0, v0, width, height, rgb, fill_outside);
        for (std::size_t c = 0; c < 3; ++c, ++band) {
          band->u8.resize(n);
          for (std::size_t i = 0; i < n; ++i) band->u8[i] = rgb[3 * i + c];
        }
        break;
      }
      case MapLayer::road_distance:
        (band++)->f32 = metres;
        break;
      case MapLayer::road_prior:
        (band++)->f32 = core::road_prior_g(metres, options.prior_sigma_m);
        break;
    }
  }
  return block;
}

void require_tile(const raster::CacheReader& cache, std::int64_t col, std::int64_t row) {
  const auto& grid = cache.grid();
  if (!grid.contains_tile(col, row)) {
    throw RequestError(RequestError::Kind::not_found,
                       "tile (" + std::to_string(col) + ", " + std::to_string(row) + ") is outside the region of " +
                           cache.path().filename().string() + " (columns 0.." + std::to_string(grid.tiles_wide() - 1) +
                           ", rows 0.." + std::to_string(grid.tiles_high() - 1) + ")");
  }
}

MapBlock read_tile(raster::CacheReader& cache, MapLayer layer, std::int64_t col, std::int64_t row,
                   const LayerOptions& options) {
  require_tile(cache, col, row);
  return read_block(cache, col * raster::kTilePx, row * raster::kTilePx, raster::kTilePx, raster::kTilePx, {layer},
                    options);
}

MapBlock read_crop(raster::CacheReader& cache, double lat_deg, double lon_deg, double size_m,
                   const std::vector<MapLayer>& layers, const LayerOptions& options, double max_size_m) {
  const CropWindow w = raster::locate_crop(cache, lat_deg, lon_deg, size_m, max_size_m);
  if (layers.empty()) throw RequestError(RequestError::Kind::bad_request, "layers: no layer requested");
  return read_block(cache, w.u0, w.v0, w.size, w.size, layers, options, /*fill_outside=*/true);
}

std::string encode_npy(const MapBlock& block) {
  const bool u8 = block.all_uint8();
  const std::size_t n = cells(block.width, block.height);
  const std::size_t nb = block.bands.size();
  std::string shape = "(" + std::to_string(block.height) + ", " + std::to_string(block.width) +
                      (nb == 1 ? ")" : ", " + std::to_string(nb) + ")");
  std::string header = std::string("{'descr': '") + (u8 ? "|u1" : "<f4") + "', 'fortran_order': False, 'shape': " +
                       shape + ", }";
  // Magic (6) + version (2) + header length (2) + header, padded with spaces to a multiple of 64
  // and ended by a newline (NumPy format 1.0).
  const std::size_t unpadded = 10 + header.size() + 1;
  header.append((64 - unpadded % 64) % 64, ' ');
  header.push_back('\n');
  std::string out("\x93NUMPY\x01\x00", 8);
  out.push_back(static_cast<char>(header.size() & 0xff));
  out.push_back(static_cast<char>(header.size() >> 8));
  out += header;
  const std::size_t item = u8 ? 1 : 4;
  const std::size_t start = out.size();
  out.resize(start + n * nb * item);
  char* data = out.data() + start;
  for (std::size_t b = 0; b < nb; ++b) {
    const Band& band = block.bands[b];
    for (std::size_t i = 0; i < n; ++i) {
      char* at = data + (i * nb + b) * item;
      if (u8) {
        *at = static_cast<char>(band.u8[i]);
      } else {
        const float value = band.is_uint8 ? static_cast<float>(band.u8[i]) : band.f32[i];
        std::memcpy(at, &value, 4);
      }
    }
  }
  return out;
}

namespace {

void require_one_layer(const MapBlock& block, const char* what) {
  if (block.layers.size() != 1) {
    throw RequestError(RequestError::Kind::bad_request,
                       std::string(what) + " holds one layer; ask for one, or use format=npy or tif for several");
  }
}

std::vector<std::uint8_t> interleave_classes(const MapBlock& block) {
  const std::size_t n = cells(block.width, block.height);
  std::vector<std::uint8_t> rgb(n * 3);
  for (std::size_t i = 0; i < n; ++i) {
    for (std::size_t c = 0; c < 3; ++c) rgb[3 * i + c] = block.bands[c].u8[i];
  }
  return rgb;
}

// A warm-to-cold ramp (near / high values warm), RGB at t in [0, 1].
std::array<std::uint8_t, 3> heat(double t) {
  static constexpr std::array<std::array<double, 3>, 5> stops = {
      {{252, 255, 164}, {249, 142, 9}, {188, 55, 84}, {87, 16, 110}, {0, 0, 4}}};
  t = std::clamp(t, 0.0, 1.0) * (stops.size() - 1);
  const std::size_t i = std::min<std::size_t>(static_cast<std::size_t>(t), stops.size() - 2);
  const double f = t - static_cast<double>(i);
  std::array<std::uint8_t, 3> out{};
  for (std::size_t c = 0; c < 3; ++c) {
    out[c] = static_cast<std::uint8_t>(std::lround(stops[i][c] * (1 - f) + stops[i + 1][c] * f));
  }
  return out;
}

}  // namespace

std::vector<std::uint8_t> encode_data_png(const MapBlock& block) {
  require_one_layer(block, "a PNG");
  const std::size_t n = cells(block.width, block.height);
  switch (block.layers[0]) {
    case MapLayer::classes: return raster::encode_png_rgb8(interleave_classes(block), block.width, block.height);
    case MapLayer::road_distance: {
      std::vector<std::uint16_t> cm(n);
      for (std::size_t i = 0; i < n; ++i) cm[i] = static_cast<std::uint16_t>(std::lround(block.bands[0].f32[i] * 100.0));
      return raster::encode_png_gray16(cm, block.width, block.height);
    }
    case MapLayer::road_prior: {
      std::vector<std::uint16_t> q(n);
      for (std::size_t i = 0; i < n; ++i) q[i] = static_cast<std::uint16_t>(std::lround(block.bands[0].f32[i] * 65535.0));
      return raster::encode_png_gray16(q, block.width, block.height);
    }
  }
  return {};
}

std::vector<std::uint8_t> encode_styled_png(const MapBlock& block, std::span<const std::uint8_t> coverage) {
  require_one_layer(block, "a styled PNG");
  const std::size_t n = cells(block.width, block.height);
  std::vector<std::uint8_t> rgba(n * 4);
  switch (block.layers[0]) {
    case MapLayer::classes: {
      const auto codes = interleave_classes(block);
      const std::vector<std::uint8_t> rgb = raster::class_colours(codes);
      for (std::size_t i = 0; i < n; ++i) {
        std::copy_n(rgb.data() + 3 * i, 3, rgba.data() + 4 * i);
        const bool background = codes[3 * i] == 0 && codes[3 * i + 1] == 0 && codes[3 * i + 2] == 0;
        rgba[4 * i + 3] = background ? 0 : 255;
      }
      break;
    }
    case MapLayer::road_distance:
    case MapLayer::road_prior: {
      const bool distance = block.layers[0] == MapLayer::road_distance;
      // Distances on a square-root scale up to 100 m, so the few metres around roads stand out.
      for (std::size_t i = 0; i < n; ++i) {
        const double value = block.bands[0].f32[i];
        const double t = distance ? std::sqrt(std::min(value, 100.0) / 100.0) : 1.0 - value;
        const auto c = heat(t);
        std::copy(c.begin(), c.end(), rgba.data() + 4 * i);
        rgba[4 * i + 3] = 255;
      }
      break;
    }
  }
  if (!coverage.empty()) {
    for (std::size_t i = 0; i < n; ++i) rgba[4 * i + 3] = std::min(rgba[4 * i + 3], coverage[i]);
  }
  return raster::encode_png_rgba8(rgba, block.width, block.height);
}

CellValues read_cell(raster::CacheReader& cache, std::int64_t u, std::int64_t v, const LayerOptions& options) {
  const MapBlock block = read_block(cache, u, v, 1, 1, {MapLayer::classes, MapLayer::road_distance, MapLayer::road_prior},
                                    options);
  CellValues values;
  for (int c = 0; c < 3; ++c) values.classes[c] = block.bands[static_cast<std::size_t>(c)].u8[0];
  values.road_distance_m = block.bands[3].f32[0];
  values.road_prior = block.bands[4].f32[0];
  return values;
}

}  // namespace seqloc::serve
