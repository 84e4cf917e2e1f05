#pragma once
// GeoTIFF through GDAL (docs/serve.md): a block as a GeoTIFF in memory (served tiles and crops),
// exports of a layer as a Cloud Optimized GeoTIFF, and a VRT over a whole region cache. Every
// file carries the region CRS (WKT) and a north-up geotransform of 0.5 m cells.

#include <filesystem>
#include <functional>
#include <optional>
#include <string>

#include "seqloc/osm/projection.hpp"
#include "seqloc/raster/cache.hpp"
#include "seqloc/serve/map_layers.hpp"

namespace seqloc::serve {

/// GDAL failed, or the output cannot be written (io); the message names the file. Export options
/// that cannot be carried out (ExportOptions::validate) are usage errors.
class ExportError : public Error {
 public:
  explicit ExportError(const std::string& message, ErrorCategory category = ErrorCategory::io)
      : Error(category, message) {}
};

/// The block as a tiled GeoTIFF (Byte when every band is uint8, else Float32; deflate), bands
/// described by name.
[[nodiscard]] std::string encode_geotiff(const MapBlock& block, const osm::RegionProjection& projection);

struct ExportOptions {
  MapLayer layer = MapLayer::classes;
  /// lon/lat box; the whole region when empty. Rounded outwards to whole cells, clipped to the region.
  std::optional<osm::GeoBox> bbox;
  LayerOptions layer_options;
  /// road_distance as Float32 metres; by default it is the cache's own UInt16 centimetres with
  /// scale 0.01 and unit "m" (GDAL and QGIS show metres; half the size).
  bool float32 = false;
  /// Called with (rows done, rows in all) while the raster is read.
  std::function<void(long long, long long)> progress;

  /// Throws ExportError naming the field, its value and the constraint it breaks.
  void validate() const;
};

/// Writes one layer as a Cloud Optimized GeoTIFF at `out`, the band described by the layer's name
/// and, for road_distance, its unit (through a temporary name, renamed when
/// complete). Throws RequestError for a bbox that does not meet the region, ExportError for GDAL
/// or I/O failures.
void export_cog(raster::CacheReader& cache, const ExportOptions& options, const std::filesystem::path& out);

/// Writes a VRT at `out` over the whole cache: bands 1-3 the classes (areas, ways, nodes), band 4
/// the road distance in metres (Float32, as GDAL reads the coverage through its scale). It refers to the cache
/// by absolute path.
void write_region_vrt(const raster::CacheReader& cache, const std::filesystem::path& out);

}  // namespace seqloc::serve
