#include "seqloc/serve/geotiff.hpp"

#include <algorithm>
#include <atomic>
#include <cmath>
#include <cstdint>
#include <limits>
#include <unistd.h>

#include <cpl_conv.h>
#include <cpl_error.h>
#include <cpl_vsi.h>
#include <gdal.h>

#include "gdal_support.hpp"
#include "seqloc/core/files.hpp"

namespace seqloc::serve {
namespace {

using detail::Dataset;
using detail::gdal_message;
using detail::Options;
using detail::register_gdal;

void set_georeference(GDALDatasetH ds, double west_m, double north_m, const osm::RegionProjection& projection) {
  double transform[6] = {west_m, raster::kCellM, 0, north_m, 0, -raster::kCellM};
  GDALSetGeoTransform(ds, transform);
  GDALSetProjection(ds, projection.wkt().c_str());
}

/// Writes the block's bands at row `y_offset`: as bytes when every band is uint8, as centimetres
/// (UInt16, rounded) when `centimetres`, else as Float32.
void write_bands(GDALDatasetH ds, const MapBlock& block, int y_offset, const std::string& what,
                 bool centimetres = false) {
  const bool u8 = block.all_uint8();
  std::vector<float> converted;
  std::vector<std::uint16_t> cm;
  for (std::size_t b = 0; b < block.bands.size(); ++b) {
    const Band& band = block.bands[b];
    GDALRasterBandH h = GDALGetRasterBand(ds, static_cast<int>(b) + 1);
    void* data = nullptr;
    GDALDataType type = GDT_Float32;
    if (centimetres && !band.is_uint8) {
      // Metres that came from the cache's centimetres: the rounding gives those back exactly.
      cm.resize(band.f32.size());
      std::transform(band.f32.begin(), band.f32.end(), cm.begin(), [](float m) {
        return static_cast<std::uint16_t>(std::clamp<long>(std::lround(static_cast<double>(m) * 100.0), 0, 65535));
      });
      data = cm.data();
      type = GDT_UInt16;
    } else if (u8) {
      data = const_cast<std::uint8_t*>(band.u8.data());
      type = GDT_Byte;
    } else if (band.is_uint8) {
      converted.assign(band.u8.begin(), band.u8.end());
      data = converted.data();
    } else {
      data = const_cast<float*>(band.f32.data());
    }
    if (GDALRasterIO(h, GF_Write, 0, y_offset, block.width, block.height, data, block.width, block.height, type, 0, 0) !=
        CE_None) {
      throw ExportError(what + ": " + gdal_message());
    }
  }
}

void describe_bands(GDALDatasetH ds, const MapBlock& block) {
  for (std::size_t b = 0; b < block.bands.size(); ++b) {
    GDALSetDescription(GDALGetRasterBand(ds, static_cast<int>(b) + 1), block.bands[b].name.c_str());
  }
}

std::string unique_vsimem_name() {
  static std::atomic<unsigned long long> counter{0};
  return "/vsimem/seqloc_" + std::to_string(getpid()) + "_" + std::to_string(counter++) + ".tif";
}

}  // namespace

std::string encode_geotiff(const MapBlock& block, const osm::RegionProjection& projection) {
  register_gdal();
  const std::string name = unique_vsimem_name();
  GDALDriverH driver = GDALGetDriverByName("GTiff");
  if (!driver) throw ExportError("GDAL has no GTiff driver");
  Options options;
  options.set("COMPRESS", "DEFLATE").set("TILED", "YES").set("BLOCKXSIZE", "256").set("BLOCKYSIZE", "256");
  if (block.bands.size() > 1) options.set("INTERLEAVE", "PIXEL");
  {
    Dataset ds(GDALCreate(driver, name.c_str(), block.width, block.height, static_cast<int>(block.bands.size()),
                          block.all_uint8() ? GDT_Byte : GDT_Float32, options.get()));
    if (!ds) throw ExportError("GeoTIFF in memory: " + gdal_message());
    set_georeference(ds.get(), block.west_m, block.north_m, projection);
    describe_bands(ds.get(), block);
    write_bands(ds.get(), block, 0, "GeoTIFF in memory");
    if (!ds.close()) {
      VSIUnlink(name.c_str());
      throw ExportError("GeoTIFF in memory: " + gdal_message());
    }
  }
  vsi_l_offset length = 0;
  GByte* bytes = VSIGetMemFileBuffer(name.c_str(), &length, TRUE);
  std::string out(reinterpret_cast<const char*>(bytes), static_cast<std::size_t>(length));
  CPLFree(bytes);
  return out;
}

namespace {

/// The region-pixel window [u0, u1) x [v0, v1) covering a lon/lat box, clipped to the region.
struct Window {
  std::int64_t u0, v0, u1, v1;
};

Window window_of(const raster::CacheReader& cache, const std::optional<osm::GeoBox>& bbox) {
  const auto& grid = cache.grid();
  Window full{0, 0, grid.width_px(), grid.height_px()};
  if (!bbox) return full;
  if (!bbox->valid() || bbox->min_lat < -90 || bbox->max_lat > 90 || bbox->min_lon < -180 || bbox->max_lon > 180) {
    throw RequestError(RequestError::Kind::bad_request, "bbox: not a lon/lat box (min_lon,min_lat,max_lon,max_lat)");
  }
  // The box's outline, sampled along its edges (a Transverse Mercator image of a lon/lat box is
  // not a rectangle), gives the extent in the region CRS.
  const auto projection = cache.metadata().projection();
  constexpr double kInf = std::numeric_limits<double>::infinity();
  double x0 = kInf, y0 = kInf, x1 = -kInf, y1 = -kInf;
  constexpr int kSamples = 16;
  for (int i = 0; i <= kSamples; ++i) {
    const double f = static_cast<double>(i) / kSamples;
    const double lon = bbox->min_lon + f * (bbox->max_lon - bbox->min_lon);
    const double lat = bbox->min_lat + f * (bbox->max_lat - bbox->min_lat);
    for (const osm::GeoPoint p : {osm::GeoPoint{bbox->min_lat, lon}, osm::GeoPoint{bbox->max_lat, lon},
                                  osm::GeoPoint{lat, bbox->min_lon}, osm::GeoPoint{lat, bbox->max_lon}}) {
      const auto g = projection.forward(p);
      x0 = std::min(x0, g.x_m), x1 = std::max(x1, g.x_m), y0 = std::min(y0, g.y_m), y1 = std::max(y1, g.y_m);
    }
  }
  Window w{static_cast<std::int64_t>(std::floor((x0 - grid.min_x()) / raster::kCellM)),
           static_cast<std::int64_t>(std::floor((grid.max_y() - y1) / raster::kCellM)),
           static_cast<std::int64_t>(std::ceil((x1 - grid.min_x()) / raster::kCellM)),
           static_cast<std::int64_t>(std::ceil((grid.max_y() - y0) / raster::kCellM))};
  w.u0 = std::max(w.u0, full.u0), w.v0 = std::max(w.v0, full.v0);
  w.u1 = std::min(w.u1, full.u1), w.v1 = std::min(w.v1, full.v1);
  if (w.u0 >= w.u1 || w.v0 >= w.v1) {
    throw RequestError(RequestError::Kind::not_found, "bbox: does not meet the region of " + cache.path().string());
  }
  return w;
}

}  // namespace

void ExportOptions::validate() const {
  try {
    layer_options.validate();
  } catch (const RequestError& e) {
    throw ExportError(std::string("export options: ") + e.what(), ErrorCategory::usage);
  }
  if (bbox && !(bbox->min_lon < bbox->max_lon && bbox->min_lat < bbox->max_lat)) {
    throw ExportError("export options: bbox: must have min_lon < max_lon and min_lat < max_lat", ErrorCategory::usage);
  }
}

void export_cog(raster::CacheReader& cache, const ExportOptions& options, const std::filesystem::path& out) {
  options.validate();
  register_gdal();
  const Window w = window_of(cache, options.bbox);
  const std::int64_t width = w.u1 - w.u0, height = w.v1 - w.v0;
  if (width > INT32_MAX || height > INT32_MAX) throw ExportError(out.string() + ": the raster is too large for GDAL");
  const std::vector<MapLayer> layers{options.layer};
  const auto projection = cache.metadata().projection();

  // A tiled GeoTIFF written strip by strip, then copied into the COG layout (which needs the
  // whole raster to build its overviews). Both are temporary names beside the output.
  const std::string suffix = ".tmp-" + std::to_string(getpid());
  const std::filesystem::path staging = out.string() + suffix + "-staging.tif";
  const std::filesystem::path partial = out.string() + suffix + ".tif";
  struct Cleanup {
    std::filesystem::path a, b;
    ~Cleanup() {
      std::error_code ec;
      std::filesystem::remove(a, ec);
      std::filesystem::remove(b, ec);
    }
  } cleanup{staging, partial};

  const MapBlock probe = read_block(cache, w.u0, w.v0, 1, 1, layers, options.layer_options);
  const bool u8 = probe.all_uint8();
  const bool centimetres = options.layer == MapLayer::road_distance && !options.float32;
  const GDALDataType type = u8 ? GDT_Byte : centimetres ? GDT_UInt16 : GDT_Float32;
  const int band_count = static_cast<int>(probe.bands.size());
  {
    Options create;
    create.set("TILED", "YES").set("BLOCKXSIZE", "512").set("BLOCKYSIZE", "512").set("COMPRESS", "LZW").set("BIGTIFF",
                                                                                                           "IF_SAFER");
    if (band_count > 1) create.set("INTERLEAVE", "PIXEL");
    Dataset ds(GDALCreate(GDALGetDriverByName("GTiff"), staging.c_str(), static_cast<int>(width),
                          static_cast<int>(height), band_count, type, create.get()));
    if (!ds) throw ExportError(staging.string() + ": " + gdal_message());
    set_georeference(ds.get(), cache.grid().min_x() + static_cast<double>(w.u0) * raster::kCellM,
                     cache.grid().max_y() - static_cast<double>(w.v0) * raster::kCellM, projection);
    describe_bands(ds.get(), probe);
    if (options.layer == MapLayer::road_distance) {
      GDALRasterBandH band = GDALGetRasterBand(ds.get(), 1);
      GDALSetRasterUnitType(band, "m");
      if (centimetres) {
        GDALSetRasterScale(band, 0.01);
        GDALSetRasterOffset(band, 0.0);
      }
    }
    for (std::int64_t v = w.v0; v < w.v1; v += raster::kTilePx) {
      const int rows = static_cast<int>(std::min<std::int64_t>(raster::kTilePx, w.v1 - v));
      const MapBlock strip = read_block(cache, w.u0, v, static_cast<int>(width), rows, layers, options.layer_options);
      write_bands(ds.get(), strip, static_cast<int>(v - w.v0), staging.string(), centimetres);
      if (options.progress) options.progress(v - w.v0 + rows, height);
    }
    if (!ds.close()) throw ExportError(staging.string() + ": " + gdal_message());
  }
  {
    Dataset src(GDALOpen(staging.c_str(), GA_ReadOnly));
    if (!src) throw ExportError(staging.string() + ": " + gdal_message());
    Options cog;
    cog.set("COMPRESS", "DEFLATE").set("BLOCKSIZE", "512").set("OVERVIEWS", "AUTO").set("BIGTIFF", "IF_SAFER");
    // Class codes are categories: overviews pick a code, never average them.
    cog.set("RESAMPLING", options.layer == MapLayer::classes ? "NEAREST" : "AVERAGE");
    // Distances and priors vary smoothly: deflate on the differences between neighbours (halves
    // the UInt16 road distance of Monaco, 12.3 MB to 6.3 MB).
    if (options.layer != MapLayer::classes) cog.set("PREDICTOR", "YES");
    CPLErrorReset();
    Dataset dst(GDALCreateCopy(GDALGetDriverByName("COG"), partial.c_str(), src.get(), FALSE, cog.get(), nullptr, nullptr));
    if (!dst) throw ExportError(out.string() + ": " + gdal_message());
    if (!dst.close()) throw ExportError(out.string() + ": " + gdal_message());
  }
  core::commit_file(partial, out);
}

void write_region_vrt(const raster::CacheReader& cache, const std::filesystem::path& out) {
  register_gdal();
  const std::string source = std::filesystem::absolute(cache.path()).string();
  const std::string classes = "GPKG:" + source + ":classes";
  const std::string distance = "GPKG:" + source + ":road_distance";
  const std::filesystem::path partial = out.string() + ".tmp-" + std::to_string(getpid());
  struct Cleanup {
    std::filesystem::path p;
    ~Cleanup() {
      std::error_code ec;
      std::filesystem::remove(p, ec);
    }
  } cleanup{partial};
  {
    // GDAL's GeoPackage driver adds an alpha band to RGB tiles unless told the band count.
    Options open;
    open.set("BAND_COUNT", "3");
    Dataset src(GDALOpenEx(classes.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY, nullptr, open.get(), nullptr));
    if (!src) throw ExportError(cache.path().string() + ": GDAL cannot open the classes table: " + gdal_message());
    Dataset vrt(GDALCreateCopy(GDALGetDriverByName("VRT"), partial.c_str(), src.get(), FALSE, nullptr, nullptr, nullptr));
    if (!vrt) throw ExportError(out.string() + ": " + gdal_message());
    static const char* kNames[] = {"classes.areas", "classes.ways", "classes.nodes"};
    for (int b = 0; b < 3 && b < GDALGetRasterCount(vrt.get()); ++b) {
      GDALRasterBandH band = GDALGetRasterBand(vrt.get(), b + 1);
      GDALSetDescription(band, kNames[b]);
      GDALSetRasterColorInterpretation(band, GCI_Undefined);
    }
    // Band 4: GDAL reads the coverage's stored centimetres through its scale, as Float32 metres.
    if (GDALAddBand(vrt.get(), GDT_Float32, nullptr) != CE_None) throw ExportError(out.string() + ": " + gdal_message());
    GDALRasterBandH band = GDALGetRasterBand(vrt.get(), GDALGetRasterCount(vrt.get()));
    const std::string xml = "<SimpleSource><SourceFilename relativeToVRT=\"0\">" + distance +
                            "</SourceFilename><SourceBand>1</SourceBand></SimpleSource>";
    GDALSetMetadataItem(band, "source_0", xml.c_str(), "new_vrt_sources");
    GDALSetRasterUnitType(band, "m");
    GDALSetDescription(band, "road_distance");
    if (!vrt.close()) throw ExportError(out.string() + ": " + gdal_message());
  }
  core::commit_file(partial, out);
}

}  // namespace seqloc::serve
