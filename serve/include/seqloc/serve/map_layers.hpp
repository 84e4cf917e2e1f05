#pragma once
// The map layers seqloc serves to other tools (docs/serve.md), read from a region cache as
// north-up blocks of 0.5 m cells (conventions.md section 2):
// - `classes`: uint8 [areas, ways, nodes] codes, the cache's own encoding;
// - `road_distance`: float32 metres to the nearest road cell, clamped (the cache's UInt16 cm / 100);
// - `road_prior`: float32 g(x) = exp(-d(x)^2 / (2 sigma^2)), the unnormalised road prior of MGR
//   (conventions.md section 6, step 4), sigma = the filter's `mgr_sigma_m` unless told otherwise.
// Blocks encode to .npy, PNG and (geotiff.hpp) GeoTIFF.

#include <cstdint>
#include <optional>
#include <span>
#include <stdexcept>
#include <string>
#include <string_view>
#include <vector>

#include "seqloc/core/error.hpp"
#include "seqloc/core/road_prior.hpp"
#include "seqloc/raster/cache.hpp"
#include "seqloc/raster/crop_window.hpp"

namespace seqloc::serve {

/// A request that cannot be served as asked (a bad parameter, a point outside the region); the
/// message says which parameter and why. A usage error, or a not_found one for what is not there;
/// the HTTP layer answers 400 or 404 (http_status, service.hpp).
class RequestError : public Error {
 public:
  enum class Kind { bad_request, not_found };
  RequestError(Kind kind, const std::string& message)
      : Error(kind == Kind::bad_request ? ErrorCategory::usage : ErrorCategory::not_found, message), kind_(kind) {}
  [[nodiscard]] Kind kind() const { return kind_; }

 private:
  Kind kind_;
};

enum class MapLayer { classes, road_distance, road_prior };
inline constexpr MapLayer kAllLayers[] = {MapLayer::classes, MapLayer::road_distance, MapLayer::road_prior};

[[nodiscard]] const char* layer_name(MapLayer layer);
[[nodiscard]] std::optional<MapLayer> parse_layer(std::string_view name);
/// A comma-separated list of layer names, each at most once, in the order given.
/// Throws RequestError naming the unknown or repeated name.
[[nodiscard]] std::vector<MapLayer> parse_layer_list(std::string_view names);

/// One band of a block: its name and its values, row-major.
struct Band {
  std::string name;  ///< e.g. "classes.areas", "road_distance"
  bool is_uint8 = false;
  std::vector<std::uint8_t> u8;  ///< when is_uint8
  std::vector<float> f32;        ///< otherwise
};

/// A north-up raster of whole cells of the region grid with one or more bands.
struct MapBlock {
  int width = 0, height = 0;
  double west_m = 0, north_m = 0;  ///< region-CRS corner of the north-west cell
  std::vector<MapLayer> layers;
  std::vector<Band> bands;         ///< classes adds three bands, the others one each
  std::int64_t outside_cells = 0;  ///< cells outside the cached region (filled: background, clamp)

  [[nodiscard]] double centre_x_m() const { return west_m + width * raster::kCellM / 2; }
  [[nodiscard]] double centre_y_m() const { return north_m - height * raster::kCellM / 2; }
  /// True when every band is uint8 (then the block encodes as uint8, else as float32).
  [[nodiscard]] bool all_uint8() const;
};

struct LayerOptions {
  double prior_sigma_m = core::kRoadPriorSigmaM;  ///< sigma of road_prior (the filter's MGR default)

  /// Throws RequestError naming the field, its value and the constraint it breaks.
  void validate() const;
};

/// A block's geometry and band names, without its values (what a sidecar describes).
[[nodiscard]] MapBlock describe_block(const raster::CacheReader& cache, std::int64_t u0, std::int64_t v0, int width,
                                      int height, const std::vector<MapLayer>& layers);

/// The block of region pixels [u0, u0 + width) x [v0, v0 + height) (region pixels, conventions.md
/// section 2). Cells outside the region are filled when `fill_outside`, else CacheRangeError.
[[nodiscard]] MapBlock read_block(raster::CacheReader& cache, std::int64_t u0, std::int64_t v0, int width, int height,
                                  const std::vector<MapLayer>& layers, const LayerOptions& options,
                                  bool fill_outside = false);

/// Throws RequestError (not found) naming the tile and the region's range when (col, row) is
/// not a tile of the region.
void require_tile(const raster::CacheReader& cache, std::int64_t col, std::int64_t row);

/// One whole tile (GeoPackage column, row) of a layer.
[[nodiscard]] MapBlock read_tile(raster::CacheReader& cache, MapLayer layer, std::int64_t col, std::int64_t row,
                                 const LayerOptions& options);

/// Largest crop side served unless configured otherwise: 1,024 m (2,048 cells).
using raster::kDefaultMaxCropM;
using raster::CropWindow;


/// A square crop of side `size_m` (rounded to whole cells) around a WGS84 point, in region-grid
/// coordinates: its centre (crop_x, crop_y of conventions.md section 4) is the centre of the
/// cell holding the point (odd sides) or the cell corner nearest to it (even sides), so the crop's
/// cells are cells of the cache. Parts outside the region are filled. Throws RequestError for a
/// size <= 0 or above `max_size_m`, a point that is not a coordinate, or a point outside the region.
[[nodiscard]] MapBlock read_crop(raster::CacheReader& cache, double lat_deg, double lon_deg, double size_m,
                                 const std::vector<MapLayer>& layers, const LayerOptions& options,
                                 double max_size_m = kDefaultMaxCropM);

/// The block as a NumPy .npy file: (H, W) for one band, else (H, W, bands); uint8 when every band
/// is uint8, else float32 (little-endian, C order).
[[nodiscard]] std::string encode_npy(const MapBlock& block);

/// The block as a PNG of its data, one layer only: classes as RGB codes, road_distance as 16-bit
/// grey centimetres (the cache's encoding), road_prior as 16-bit grey g * 65535.
/// Throws RequestError for several layers.
[[nodiscard]] std::vector<std::uint8_t> encode_data_png(const MapBlock& block);

/// The block as a picture for people: classes in the colours of seqloc's pictures, road distance
/// and road prior as a heat map (near/high = warm); RGBA, transparent where classes are background.
/// `coverage` (one byte per cell, when given) caps the alpha: 0 where the block has no data.
[[nodiscard]] std::vector<std::uint8_t> encode_styled_png(const MapBlock& block,
                                                          std::span<const std::uint8_t> coverage = {});

/// The value of each band at one cell, for `point` queries.
struct CellValues {
  std::uint8_t classes[3] = {0, 0, 0};
  double road_distance_m = 0;
  double road_prior = 0;
};
[[nodiscard]] CellValues read_cell(raster::CacheReader& cache, std::int64_t u, std::int64_t v,
                                   const LayerOptions& options);

}  // namespace seqloc::serve
