#include "seqloc/serve/web_mercator.hpp"

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
#include <memory>
#include <string>

#include <gdal_utils.h>
#include <ogr_spatialref.h>

#include "gdal_support.hpp"

#include "seqloc/core/angles.hpp"
#include "seqloc/core/error.hpp"

namespace seqloc::serve {
namespace {

/// Half the width of the Web Mercator world, metres (pi times the WGS84 semi-major axis).
constexpr double kHalfWorldM = 20037508.342789244;

RequestError not_found(const std::string& message) { return {RequestError::Kind::not_found, message}; }

std::string number(double value) {
  char text[40];
  std::snprintf(text, sizeof text, "%.17g", value);
  return text;
}

/// The region pixels under a tile: its bounds taken to the region CRS along its edges (a tile's
/// outline is curved there), widened by two cells for the bilinear kernel, clipped to the region.
struct PixelWindow {
  std::int64_t u0 = 0, v0 = 0, u1 = 0, v1 = 0;
  [[nodiscard]] bool empty() const { return u1 <= u0 || v1 <= v0; }
};

// EPSG:3857 as WKT, made once: naming it by its code looks it up in PROJ's database (SQLite) for
// every tile.
const std::string& web_mercator_wkt() {
  static const std::string wkt = [] {
    OGRSpatialReference mercator;
    mercator.importFromEPSG(3857);
    char* text = nullptr;
    mercator.exportToWkt(&text);
    std::string out = text != nullptr ? text : "";
    CPLFree(text);
    return out;
  }();
  return wkt;
}

// The region-CRS point of a Web Mercator point (spherical Mercator's inverse, then the region's
// own projection): closed forms, where a GDAL transformation costs a search of PROJ's database
// each time it is made.
osm::GridPoint mercator_to_region(const osm::RegionProjection& projection, double x, double y) {
  constexpr double kEarthRadiusM = 6378137.0;
  const double lon = x / kEarthRadiusM * core::kRadToDeg;
  const double lat = std::atan(std::sinh(y / kEarthRadiusM)) * core::kRadToDeg;
  return projection.forward(osm::GeoPoint{lat, lon});
}

PixelWindow region_pixels_under(const raster::CacheReader& cache, const WebBounds& b) {
  const osm::RegionProjection projection = cache.metadata().projection();
  constexpr int kSteps = 16;
  double min_x = std::numeric_limits<double>::infinity(), max_x = -min_x, min_y = min_x, max_y = -min_x;
  for (int i = 0; i <= kSteps; ++i) {
    const double t = static_cast<double>(i) / kSteps;
    const double xs[4] = {b.west + t * (b.east - b.west), b.west + t * (b.east - b.west), b.west, b.east};
    const double ys[4] = {b.south, b.north, b.south + t * (b.north - b.south), b.south + t * (b.north - b.south)};
    for (int k = 0; k < 4; ++k) {
      const osm::GridPoint p = mercator_to_region(projection, xs[k], ys[k]);
      min_x = std::min(min_x, p.x_m), max_x = std::max(max_x, p.x_m);
      min_y = std::min(min_y, p.y_m), max_y = std::max(max_y, p.y_m);
    }
  }
  if (!(min_x <= max_x && min_y <= max_y)) return {};
  const auto& g = cache.grid();
  PixelWindow w;
  w.u0 = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::floor((min_x - g.min_x()) / raster::kCellM)) - 2);
  w.u1 = std::min<std::int64_t>(g.width_px(),
                                static_cast<std::int64_t>(std::ceil((max_x - g.min_x()) / raster::kCellM)) + 2);
  w.v0 = std::max<std::int64_t>(0, static_cast<std::int64_t>(std::floor((g.max_y() - max_y) / raster::kCellM)) - 2);
  w.v1 = std::min<std::int64_t>(g.height_px(),
                                static_cast<std::int64_t>(std::ceil((g.max_y() - min_y) / raster::kCellM)) + 2);
  return w;
}

/// GDALWarpAppOptions freed on scope exit.
struct WarpOptions {
  explicit WarpOptions(const std::vector<std::string>& args) {
    std::vector<char*> argv;
    argv.reserve(args.size() + 1);
    for (const auto& a : args) argv.push_back(const_cast<char*>(a.c_str()));
    argv.push_back(nullptr);
    options = GDALWarpAppOptionsNew(argv.data(), nullptr);
  }
  ~WarpOptions() { GDALWarpAppOptionsFree(options); }
  WarpOptions(const WarpOptions&) = delete;
  WarpOptions& operator=(const WarpOptions&) = delete;
  GDALWarpAppOptions* options = nullptr;
};

}  // namespace

WebZooms web_zooms(const raster::CacheMetadata& metadata) {
  // Ground size of a 256 px tile's pixel at zoom 0 and this latitude, metres.
  const double zoom0_pixel_m = 2 * kHalfWorldM / 256.0 * std::cos(metadata.centre_lat * core::kDegToRad);
  WebZooms z;
  z.max_zoom = std::clamp(static_cast<int>(std::lround(std::log2(zoom0_pixel_m / raster::kCellM))), 3, 24);
  z.min_zoom = z.max_zoom - 3;
  return z;
}

WebBounds web_tile_bounds(int z, std::int64_t x, std::int64_t y) {
  const double size = 2 * kHalfWorldM / std::ldexp(1.0, z);
  WebBounds b;
  b.west = -kHalfWorldM + static_cast<double>(x) * size;
  b.east = b.west + size;
  b.north = kHalfWorldM - static_cast<double>(y) * size;
  b.south = b.north - size;
  return b;
}

namespace {

// `source`, the region pixels `w` of the cache, as an in-memory GDAL dataset in the region CRS.
detail::Dataset region_dataset(raster::CacheReader& cache, const PixelWindow& w, const MapBlock& source) {
  detail::register_gdal();
  const int width = static_cast<int>(w.u1 - w.u0), height = static_cast<int>(w.v1 - w.v0);
  const bool bytes = source.all_uint8();
  const GDALDataType type = bytes ? GDT_Byte : GDT_Float32;
  const int band_count = static_cast<int>(source.bands.size());
  detail::Dataset src(GDALCreate(GDALGetDriverByName("MEM"), "", width, height, band_count, type, nullptr));
  if (!src) throw Error(ErrorCategory::internal, "GDAL cannot create an in-memory raster: " + detail::gdal_message());
  const auto& g = cache.grid();
  double transform[6] = {g.min_x() + static_cast<double>(w.u0) * raster::kCellM,
                         raster::kCellM,
                         0,
                         g.max_y() - static_cast<double>(w.v0) * raster::kCellM,
                         0,
                         -raster::kCellM};
  GDALSetGeoTransform(src.get(), transform);
  GDALSetProjection(src.get(), cache.metadata().projection().wkt().c_str());
  for (int b = 0; b < band_count; ++b) {
    const Band& band = source.bands[static_cast<std::size_t>(b)];
    void* data = bytes ? static_cast<void*>(const_cast<std::uint8_t*>(band.u8.data()))
                       : static_cast<void*>(const_cast<float*>(band.f32.data()));
    if (GDALRasterIO(GDALGetRasterBand(src.get(), b + 1), GF_Write, 0, 0, width, height, data, width, height, type, 0,
                     0) != CE_None) {
      throw Error(ErrorCategory::internal, "GDAL cannot fill an in-memory raster: " + detail::gdal_message());
    }
  }
  return src;
}

// The warped dataset's bands (named as `source`'s) and its alpha band as a tile.
WebTile warped_tile(GDALDatasetH dst, const MapBlock& source, MapLayer layer, const WebBounds& bounds, int tile_px) {
  const bool bytes = source.all_uint8();
  const GDALDataType type = bytes ? GDT_Byte : GDT_Float32;
  const int band_count = static_cast<int>(source.bands.size());
  WebTile tile;
  tile.block.width = tile.block.height = tile_px;
  tile.block.west_m = bounds.west;
  tile.block.north_m = bounds.north;
  tile.block.layers = {layer};
  const std::size_t n = static_cast<std::size_t>(tile_px) * static_cast<std::size_t>(tile_px);
  for (int b = 0; b < band_count; ++b) {
    Band band;
    band.name = source.bands[static_cast<std::size_t>(b)].name;
    band.is_uint8 = bytes;
    void* data = nullptr;
    if (bytes) {
      band.u8.resize(n);
      data = band.u8.data();
    } else {
      band.f32.resize(n);
      data = band.f32.data();
    }
    if (GDALRasterIO(GDALGetRasterBand(dst, b + 1), GF_Read, 0, 0, tile_px, tile_px, data, tile_px, tile_px, type, 0,
                     0) != CE_None) {
      throw Error(ErrorCategory::internal, "GDAL cannot read a warped tile: " + detail::gdal_message());
    }
    tile.block.bands.push_back(std::move(band));
  }
  tile.covered.resize(n);
  if (GDALRasterIO(GDALGetRasterBand(dst, band_count + 1), GF_Read, 0, 0, tile_px, tile_px, tile.covered.data(),
                   tile_px, tile_px, GDT_Byte, 0, 0) != CE_None) {
    throw Error(ErrorCategory::internal, "GDAL cannot read a warped tile's alpha: " + detail::gdal_message());
  }
  return tile;
}

}  // namespace

WebTile read_web_tile(raster::CacheReader& cache, MapLayer layer, int z, std::int64_t x, std::int64_t y, int tile_px,
                      const LayerOptions& options) {
  const WebZooms zooms = web_zooms(cache.metadata());
  if (z < zooms.min_zoom || z > zooms.max_zoom) {
    throw not_found("zoom " + std::to_string(z) + " is outside this region's zooms " + std::to_string(zooms.min_zoom) +
                    ".." + std::to_string(zooms.max_zoom));
  }
  const std::int64_t tiles = std::int64_t{1} << z;
  if (x < 0 || y < 0 || x >= tiles || y >= tiles) {
    throw not_found("tile " + std::to_string(z) + "/" + std::to_string(x) + "/" + std::to_string(y) +
                    " does not exist (x and y are in 0.." + std::to_string(tiles - 1) + " at zoom " +
                    std::to_string(z) + ")");
  }
  const WebBounds bounds = web_tile_bounds(z, x, y);
  const PixelWindow w = region_pixels_under(cache, bounds);
  if (w.empty()) {
    throw not_found("tile " + std::to_string(z) + "/" + std::to_string(x) + "/" + std::to_string(y) +
                    " does not meet the region (see bounds in tilejson.json)");
  }
  const int width = static_cast<int>(w.u1 - w.u0), height = static_cast<int>(w.v1 - w.v0);
  const MapBlock source = read_block(cache, w.u0, w.v0, width, height, {layer}, options);

  // The source as an in-memory GDAL dataset in the region CRS, warped by gdalwarp's own code.
  const detail::Dataset src = region_dataset(cache, w, source);
  const WarpOptions warp({"-of", "MEM", "-t_srs", web_mercator_wkt(), "-te", number(bounds.west), number(bounds.south),
                          number(bounds.east), number(bounds.north), "-ts", std::to_string(tile_px),
                          std::to_string(tile_px), "-r", layer == MapLayer::classes ? "near" : "bilinear", "-dstalpha",
                          "-q"});
  if (!warp.options) throw Error(ErrorCategory::internal, "GDAL refused the warp options: " + detail::gdal_message());
  GDALDatasetH sources[] = {src.get()};
  int usage_error = 0;
  CPLErrorReset();
  detail::Dataset dst(GDALWarp("", nullptr, 1, sources, warp.options, &usage_error));
  if (!dst)
    throw Error(ErrorCategory::internal, "GDAL could not warp tile " + std::to_string(z) + "/" + std::to_string(x) +
                                             "/" + std::to_string(y) + ": " + detail::gdal_message());
  return warped_tile(dst.get(), source, layer, bounds, tile_px);
}

}  // namespace seqloc::serve
