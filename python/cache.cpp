// Region caches (seqloc.Cache) and their crops (seqloc.Crop, seqloc.CacheInfo).

#include "bindings.hpp"

namespace seqloc::python {
namespace {

class PyCache {
 public:
  PyCache(const std::string& path, std::size_t lru_tiles)
      : cache_(std::make_unique<raster::CacheReader>(path, lru_tiles)), identity_(cache_identity(*cache_)) {}

  /// The layers asked for ((H, W, 3) uint8 classes, (H, W) float32 road distance in metres and
  /// road prior) and the crop's georeference.
  Crop crop(const py::object& lat, const py::object& lon, double size_m, const std::vector<std::string>& layers,
            double prior_sigma_m, double max_size_m, const py::object& x, const py::object& y) {
    const PointArgument at =
        point_argument(lat, lon, x, y, "crop: give lat and lon (WGS84), or x and y (region CRS metres)");
    for (const auto& name : layers) {
      if (name != "classes" && name != "road_distance" && name != "road_prior") {
        throw seqloc::UsageError("unknown layer '" + name + "' (classes, road_distance, road_prior)");
      }
    }
    raster::CropWindow w;
    {
      py::gil_scoped_release release;
      w = at.geo ? raster::locate_crop(*cache_, at.a, at.b, size_m, max_size_m)
                 : raster::locate_crop_xy(*cache_, at.a, at.b, size_m, max_size_m);
    }
    Crop out = georeference(w);
    const auto n = static_cast<py::ssize_t>(w.size);
    const auto wanted = [&](const char* name) { return std::find(layers.begin(), layers.end(), name) != layers.end(); };
    if (wanted("classes")) {
      std::vector<std::uint8_t> rgb;
      {
        py::gil_scoped_release release;
        cache_->read_classes(w.u0, w.v0, w.size, w.size, rgb, true);
      }
      out.classes = adopt(std::move(rgb), {n, n, 3});
    }
    if (wanted("road_distance") || wanted("road_prior")) {
      std::vector<float> metres;
      {
        py::gil_scoped_release release;
        cache_->read_road_distance_m(w.u0, w.v0, w.size, w.size, metres, true);
      }
      // The served layers' values: raster's metres, the filter's g.
      if (wanted("road_prior")) out.road_prior = adopt(filter::road_prior_g(metres, prior_sigma_m), {n, n});
      if (wanted("road_distance")) out.road_distance = adopt(std::move(metres), {n, n});
    }
    return out;
  }

  [[nodiscard]] CacheInfo info() const {
    const auto& m = cache_->metadata();
    return {cache_->path().string(),
            m.source_file,
            m.projection().wkt(),
            m.centre_lat,
            m.centre_lon,
            m.max_distance_m,
            {m.grid.tiles_wide(), m.grid.tiles_high()},
            {m.grid.min_x(), m.grid.min_y(), m.grid.max_x(), m.grid.max_y()}};
  }

  [[nodiscard]] std::pair<double, double> to_grid(double lat, double lon) const {
    const auto p = cache_->metadata().projection().forward({lat, lon});
    return {p.x_m, p.y_m};
  }

  [[nodiscard]] std::pair<double, double> from_grid(double x, double y) const {
    double convergence = 0;
    const auto g = cache_->metadata().projection().reverse({x, y}, convergence);
    return {g.lat_deg, g.lon_deg};
  }

 private:
  // A crop window's centre, cell size, geotransform and CRS.
  [[nodiscard]] Crop georeference(const raster::CropWindow& w) const {
    const auto& grid = cache_->grid();
    const double west = grid.min_x() + static_cast<double>(w.u0) * raster::kCellM;
    const double north = grid.max_y() - static_cast<double>(w.v0) * raster::kCellM;
    Crop out;
    out.crop_x = west + w.size * raster::kCellM / 2;
    out.crop_y = north - w.size * raster::kCellM / 2;
    out.geotransform = py::make_tuple(west, raster::kCellM, 0.0, north, 0.0, -raster::kCellM);
    out.crs_wkt = cache_->metadata().projection().wkt();
    out.cache_path = identity_;
    return out;
  }

  std::unique_ptr<raster::CacheReader> cache_;
  std::string identity_;  ///< cache_identity(*cache_)
};

}  // namespace

void bind_map_results(py::module_& m) {
  py::class_<Crop>(m, "Crop", "A north-up map crop around a point (Cache.crop)")
      .def_readonly("classes", &Crop::classes, "(H, W, 3) uint8 class masks, or None when not asked for")
      .def_readonly("road_distance", &Crop::road_distance, "(H, W) float32 metres to the nearest road, or None")
      .def_readonly("road_prior", &Crop::road_prior, "(H, W) float32 road prior g in [0, 1], or None")
      .def_readonly("crop_x", &Crop::crop_x, "The crop's centre, region CRS metres (east)")
      .def_readonly("crop_y", &Crop::crop_y, "The crop's centre, region CRS metres (north)")
      .def_readonly("cell_m", &Crop::cell_m, "Metres per cell")
      .def_readonly("geotransform", &Crop::geotransform, "GDAL's geotransform of the crop's cells")
      .def_readonly("crs_wkt", &Crop::crs_wkt, "The region CRS as WKT")
      .def_readonly("cache_path", &Crop::cache_path, "The cache it was cut from (absolute)");
  py::class_<CacheInfo>(m, "CacheInfo", "What a region cache holds (Cache.info)")
      .def_readonly("path", &CacheInfo::path)
      .def_readonly("source_file", &CacheInfo::source_file, "The .osm.pbf it was made from")
      .def_readonly("centre_lat", &CacheInfo::centre_lat)
      .def_readonly("centre_lon", &CacheInfo::centre_lon)
      .def_readonly("tiles", &CacheInfo::tiles, "(wide, high)")
      .def_readonly("extent", &CacheInfo::extent, "(min_x, min_y, max_x, max_y), region CRS metres")
      .def_readonly("max_distance_m", &CacheInfo::max_distance_m, "Road distances are clamped here")
      .def_readonly("crs_wkt", &CacheInfo::crs_wkt);
}

void bind_cache(py::module_& m) {
  py::class_<PyCache>(m, "Cache", "A region cache (GeoPackage) opened read-only")
      .def(py::init<const std::string&, std::size_t>(), py::arg("path"), py::arg("lru_tiles") = 64)
      .def("crop", &PyCache::crop, py::arg("lat") = py::none(), py::arg("lon") = py::none(), py::arg("size_m") = 128.0,
           py::arg("layers") = std::vector<std::string>{"classes", "road_distance", "road_prior"},
           py::arg("prior_sigma_m") = filter::FilterConfig{}.mgr_sigma_m,
           py::arg("max_size_m") = raster::kDefaultMaxCropM, py::kw_only(), py::arg("x") = py::none(),
           py::arg("y") = py::none(),
           "North-up crop in region-grid cells (conventions.md section 4: crop_x, crop_y) around a WGS84 point "
           "(lat, lon) or a region point in metres (x=, y=); the layers not asked for are None")
      .def("to_grid", &PyCache::to_grid, py::arg("lat"), py::arg("lon"), "(x, y) in the region CRS, metres")
      .def("from_grid", &PyCache::from_grid, py::arg("x"), py::arg("y"),
           "(lat, lon) of a region point (to_grid's inverse)")
      .def_property_readonly("info", &PyCache::info, "What the cache holds: a CacheInfo");
}

}  // namespace seqloc::python
