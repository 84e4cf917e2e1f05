// The `seqloc` Python module (docs/python.md): region caches and the SeqLoc filter for Python
// tools, e.g. a PyTorch loop that feeds a backbone the map crop around a GPS fix and runs SeqLoc
// online on its output. Arrays come back as NumPy arrays that own the C++ buffers (no copies);
// volumes go in as NumPy arrays read in place.

#include <algorithm>
#include <array>
#include <cstring>
#include <memory>
#include <optional>
#include <span>
#include <string>
#include <type_traits>
#include <utility>
#include <variant>
#include <vector>

#include <pybind11/numpy.h>
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include "seqloc/core/error.hpp"
#include "seqloc/filter/seqloc_filter.hpp"
#include "seqloc/filter/types.hpp"
#include "seqloc/pipeline/backbone_calibration.hpp"
#include "seqloc/pipeline/frame_store.hpp"
#include "seqloc/pipeline/localize.hpp"
#include "seqloc/pipeline/sequential_localizer.hpp"
#include "seqloc/raster/cache.hpp"
#include "seqloc/raster/crop_window.hpp"

namespace py = pybind11;
namespace filter = seqloc::filter;
namespace io = seqloc::io;
namespace pipeline = seqloc::pipeline;
namespace raster = seqloc::raster;

namespace {

/// A NumPy array that takes ownership of a vector's buffer.
template <class T>
py::array_t<T> adopt(std::vector<T>&& values, std::vector<py::ssize_t> shape) {
  auto* owner = new std::vector<T>(std::move(values));
  py::capsule free_owner(owner, [](void* p) { delete static_cast<std::vector<T>*>(p); });
  return py::array_t<T>(shape, owner->data(), free_owner);
}

/// Any array a Python user holds, read in place where its memory allows: a NumPy array, an object
/// with __dlpack__ (a CPU torch tensor, JAX, CuPy after .get()), or one with __array__. The error
/// names the argument and the type, never the array's values.
py::array as_array(const py::object& value, const char* name) {
  if (py::isinstance<py::array>(value)) return py::reinterpret_borrow<py::array>(value);
  try {
    if (py::hasattr(value, "__dlpack__")) return py::module_::import("numpy").attr("from_dlpack")(value);
    if (py::hasattr(value, "__array__")) return py::array::ensure(value);
  } catch (const py::error_already_set& e) {
    throw py::type_error(std::string(name) + ": cannot read a " + std::string(py::str(py::type::of(value).attr("__name__"))) +
                         " as an array in memory (" + std::string(py::str(e.value())).substr(0, 200) + ")");
  }
  throw py::type_error(std::string(name) + ": expected an array (NumPy, DLPack or __array__), got " +
                       std::string(py::str(py::type::of(value).attr("__name__"))));
}

/// Three numbers from any sequence of them; a short TypeError naming the argument otherwise.
std::array<double, 3> three_numbers(const py::object& value, const char* name, const char* what) {
  try {
    const auto t = value.cast<std::tuple<double, double, double>>();
    return {std::get<0>(t), std::get<1>(t), std::get<2>(t)};
  } catch (const py::cast_error&) {
    throw py::type_error(std::string(name) + ": expected three numbers " + what + ", got a " +
                         std::string(py::str(py::type::of(value).attr("__name__"))));
  }
}

/// A point given either as (lat, lon) or as region metres (x, y), exactly one pair of the two.
struct PointArgument {
  bool geo = false;
  double a = 0, b = 0;  ///< lat, lon or x, y
};
PointArgument point_argument(const py::object& lat, const py::object& lon, const py::object& x, const py::object& y,
                             const char* message) {
  const bool geo = !lat.is_none() || !lon.is_none(), metres = !x.is_none() || !y.is_none();
  if (geo == metres || (geo && (lat.is_none() || lon.is_none())) || (metres && (x.is_none() || y.is_none()))) {
    throw py::type_error(message);
  }
  return geo ? PointArgument{true, lat.cast<double>(), lon.cast<double>()}
             : PointArgument{false, x.cast<double>(), y.cast<double>()};
}

class PyCache {
 public:
  PyCache(const std::string& path, std::size_t lru_tiles) : cache_(std::make_unique<raster::CacheReader>(path, lru_tiles)) {}

  /// {"classes": (H, W, 3) uint8, "road_distance": (H, W) float32 metres, "road_prior": (H, W)
  /// float32, plus the crop's georeference}.
  py::dict crop(const py::object& lat, const py::object& lon, double size_m, const std::vector<std::string>& layers,
                double prior_sigma_m, double max_size_m, const py::object& x, const py::object& y) {
    const PointArgument at =
        point_argument(lat, lon, x, y, "crop: give lat and lon (WGS84), or x and y (region CRS metres)");
    raster::CropWindow w;
    {
      py::gil_scoped_release release;
      w = at.geo ? raster::locate_crop(*cache_, at.a, at.b, size_m, max_size_m)
                 : raster::locate_crop_xy(*cache_, at.a, at.b, size_m, max_size_m);
    }
    const auto n = static_cast<py::ssize_t>(w.size);
    py::dict out;
    const auto& grid = cache_->grid();
    const double west = grid.min_x() + static_cast<double>(w.u0) * raster::kCellM;
    const double north = grid.max_y() - static_cast<double>(w.v0) * raster::kCellM;
    out["crop_x"] = west + w.size * raster::kCellM / 2;
    out["crop_y"] = north - w.size * raster::kCellM / 2;
    out["cell_m"] = raster::kCellM;
    out["geotransform"] = py::make_tuple(west, raster::kCellM, 0.0, north, 0.0, -raster::kCellM);
    out["crs_wkt"] = cache_->metadata().projection().wkt();
    for (const auto& name : layers) {
      if (name != "classes" && name != "road_distance" && name != "road_prior") {
        throw py::value_error("unknown layer '" + name + "' (classes, road_distance, road_prior)");
      }
    }
    std::vector<float> metres;
    for (const auto& name : layers) {
      if (name == "classes") {
        std::vector<std::uint8_t> rgb;
        {
          py::gil_scoped_release release;
          cache_->read_classes(w.u0, w.v0, w.size, w.size, rgb, true);
        }
        out["classes"] = adopt(std::move(rgb), {n, n, 3});
        continue;
      }
      if (metres.empty()) {
        py::gil_scoped_release release;
        cache_->read_road_distance_m(w.u0, w.v0, w.size, w.size, metres, true);
      }
      // The served layers' values: raster's metres, the filter's g.
      out[py::str(name)] = name == "road_distance" ? adopt(std::vector<float>(metres), {n, n})
                                                   : adopt(filter::road_prior_g(metres, prior_sigma_m), {n, n});
    }
    return out;
  }

  py::dict info() const {
    const auto& m = cache_->metadata();
    py::dict d;
    d["path"] = cache_->path().string();
    d["source_file"] = m.source_file;
    d["centre_lat"] = m.centre_lat;
    d["centre_lon"] = m.centre_lon;
    d["tiles"] = py::make_tuple(m.grid.tiles_wide(), m.grid.tiles_high());
    d["extent"] = py::make_tuple(m.grid.min_x(), m.grid.min_y(), m.grid.max_x(), m.grid.max_y());
    d["max_distance_m"] = m.max_distance_m;
    d["crs_wkt"] = m.projection().wkt();
    return d;
  }

  py::tuple to_grid(double lat, double lon) const {
    const auto p = cache_->metadata().projection().forward({lat, lon});
    return py::make_tuple(p.x_m, p.y_m);
  }

  py::tuple from_grid(double x, double y) const {
    double convergence = 0;
    const auto g = cache_->metadata().projection().reverse({x, y}, convergence);
    return py::make_tuple(g.lat_deg, g.lon_deg);
  }

 private:
  std::unique_ptr<raster::CacheReader> cache_;
};

// The filter's settings by name, from filter::filter_config_fields (the one list of them).
filter::FilterConfig config_from(const py::dict& d) {
  // "preset": "paper" starts from the seed paper's configuration; the other keys override it.
  filter::FilterConfig c;
  if (d.contains("preset")) {
    const auto preset = d["preset"].cast<std::string>();
    if (preset != "paper") throw py::value_error("preset '" + preset + "': the one preset is 'paper'");
    c = filter::paper_config();
  }
  const auto fields = filter::filter_config_fields();
  for (const auto& item : d) {
    const auto key = item.first.cast<std::string>();
    if (key == "preset") continue;
    const py::handle value = item.second;
    const auto field = std::find_if(fields.begin(), fields.end(), [&](const auto& f) { return key == f.name; });
    if (field == fields.end()) throw py::key_error("unknown filter setting '" + key + "' (Filter.settings() lists them)");
    std::visit([&](auto member) { c.*member = value.cast<std::remove_reference_t<decltype(c.*member)>>(); }, field->member);
  }
  c.validate();
  return c;
}

py::dict config_dict(const filter::FilterConfig& c) {
  py::dict d;
  for (const auto& field : filter::filter_config_fields()) {
    std::visit([&](auto member) { d[field.name] = c.*member; }, field.member);
  }
  return d;
}

// Every setting with its default and what it is: {name: (default, help)}.
py::dict filter_settings() {
  const filter::FilterConfig defaults;
  py::dict d;
  for (const auto& field : filter::filter_config_fields()) {
    std::visit([&](auto member) { d[field.name] = py::make_tuple(defaults.*member, field.help); }, field.member);
  }
  return d;
}

py::dict pose_dict(const filter::Pose& p) {
  py::dict d;
  d["u"] = p.u;
  d["v"] = p.v;
  d["heading_deg"] = p.heading_deg;
  return d;
}

/// A belief's position marginal as a (height, width) float32 array.
py::array_t<float> marginal_array(const filter::BeliefVolume& belief) {
  return adopt(belief.position_marginal(), {belief.height(), belief.width()});
}

/// A volume argument as the filter reads it: (H, W, N) float32 or float16, C order, kept alive by
/// `holder`.
filter::FrameVolume volume_view(const py::object& value, bool probabilities, double cell_m, py::array& holder) {
  const py::array volume = as_array(value, "log_volume");
  if (volume.ndim() != 3) {
    throw py::value_error("log_volume: expected shape (H, W, N), got " + std::to_string(volume.ndim()) + " dimensions");
  }
  filter::FrameVolume view;
  if (py::isinstance<py::array_t<float>>(volume)) {
    holder = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(volume);
    view.type = filter::VolumeType::float32;
  } else if (volume.dtype().kind() == 'f' && volume.dtype().itemsize() == 2) {
    holder = py::array::ensure(volume, py::array::c_style);
    view.type = filter::VolumeType::float16;
  } else {
    throw py::value_error("log_volume: expected float32 or float16, got dtype " + std::string(py::str(volume.dtype())));
  }
  view.data = holder.data();
  view.values = probabilities ? filter::VolumeValues::prob : filter::VolumeValues::log_prob;
  view.height = static_cast<int>(volume.shape(0));
  view.width = static_cast<int>(volume.shape(1));
  view.bins = static_cast<int>(volume.shape(2));
  view.cell_m = cell_m;
  return view;
}

class PyFilter {
 public:
  explicit PyFilter(const py::dict& config) : filter_(config_from(config)) {}
  [[nodiscard]] const filter::FilterConfig& config() const { return filter_.config(); }

  void reset(const py::object& gps) {
    if (gps.is_none()) {
      filter_.reset_uniform();
    } else {
      const auto t = gps.cast<std::tuple<double, double, double>>();
      filter_.reset_gaussian(std::get<0>(t), std::get<1>(t), std::get<2>(t));
    }
  }

  py::dict step(const py::object& volume_in, const py::object& odometry_in, const py::object& crop_pose_in,
                const py::object& road_distance, bool probabilities, double cell_m) {
    py::array holder;
    const filter::FrameVolume view = volume_view(volume_in, probabilities, cell_m, holder);
    const auto odometry = three_numbers(odometry_in, "odometry", "(forward_m, left_m, yaw_deg)");
    const filter::Odometry odo{odometry[0], odometry[1], odometry[2]};
    // Without a crop pose the volume is centred on the window, north-up (not at its corner).
    const auto& c = filter_.config();
    filter::CropPose crop{(c.width - 1) / 2.0, (c.height - 1) / 2.0, 0.0};
    if (!crop_pose_in.is_none()) {
      const auto t = three_numbers(crop_pose_in, "crop_pose", "(centre_u, centre_v, rotation_deg)");
      crop = {t[0], t[1], t[2]};
    }

    py::array_t<float, py::array::c_style | py::array::forcecast> distance;
    std::span<const float> distance_window;
    if (!road_distance.is_none()) {
      distance = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(as_array(road_distance, "road_distance"));
      if (!distance || distance.ndim() != 2 || distance.shape(0) != c.height || distance.shape(1) != c.width) {
        throw py::value_error("road_distance: expected a (" + std::to_string(c.height) + ", " + std::to_string(c.width) +
                              ") float array, the window's size");
      }
      distance_window = {distance.data(), static_cast<std::size_t>(distance.size())};
    } else if (c.mgr) {
      throw py::value_error("road_distance: MGR is on and needs the window's road distance (or set mgr=False)");
    }
    filter::FrameResult r;
    {
      py::gil_scoped_release release;
      const auto frame = filter::prepare_frame(view, c.headings, c.threads);
      r = filter_.step(frame, crop, odo, distance_window);
    }
    py::dict d = pose_dict(r.pose);
    d["argmax"] = pose_dict(r.argmax);
    d["frame_entropy"] = r.frame_entropy;
    d["etu_weight"] = r.etu_weight;
    d["volume_power"] = r.volume_power;
    d["relocalized"] = r.relocalized;
    d["peak_log_belief"] = r.peak_log_belief;
    return d;
  }

  void recentre(int du, int dv) { filter_.recentre(du, dv); }

  /// The belief summed over headings, (height, width) float32: a probability per window cell.
  py::array_t<float> belief_marginal() const { return marginal_array(filter_.belief()); }

 private:
  filter::SeqLocFilter filter_;
};

/// seqloc localize's online and seqloc modes, one frame at a time: the window over the region,
/// its road distances and re-centring, the frames prepared and rounded exactly as localize
/// prepares a route's (pipeline::SequentialLocalizer, the class localize itself drives).
class PyLocalizer {
 public:
  PyLocalizer(const std::string& cache, const py::dict& config, const std::string& mode, double volume_temperature,
              double recentre_margin, const std::optional<std::string>& calibration, int lag)
      : cache_(std::make_unique<raster::CacheReader>(cache)) {
    if (lag < 0) throw py::value_error("lag: must be >= 0 frames, got " + std::to_string(lag));
    if (mode != "seqloc" && mode != "online") throw py::value_error("mode: 'seqloc' or 'online', got '" + mode + "'");
    options_.filter = config_from(config);
    options_.volume_temperature = volume_temperature;
    options_.recentre_margin = recentre_margin;
    if (calibration) pipeline::apply_calibration_file(*calibration, options_);
    options_.validate();
    localizer_ = std::make_unique<pipeline::SequentialLocalizer>(*cache_, options_.filter, mode == "online",
                                                                 recentre_margin, lag);
  }

  py::dict step(const py::object& volume_in, const py::object& odometry_in, const py::object& crop_lat,
                const py::object& crop_lon, const py::object& crop_x, const py::object& crop_y, const py::object& gps,
                bool probabilities, double cell_m) {
    py::array holder;
    const filter::FrameVolume view = volume_view(volume_in, probabilities, cell_m, holder);
    const auto odometry = three_numbers(odometry_in, "odometry", "(forward_m, left_m, yaw_deg)");
    // The frame as a route row would hold it: its crop, lat/lon or region metres.
    io::RouteFrame f;
    f.frame = std::to_string(frames_);
    f.timestamp_s = static_cast<double>(frames_);
    const PointArgument centre =
        point_argument(crop_lat, crop_lon, crop_x, crop_y,
                       "step: give the crop's centre as crop_lat and crop_lon, or as crop_x and crop_y");
    const auto& projection = cache_->metadata().projection();
    if (centre.geo) {
      f.crop_geo = seqloc::osm::GeoPoint{centre.a, centre.b};
    } else {
      f.crop_grid = seqloc::osm::GridPoint{centre.a, centre.b};
    }
    std::optional<pipeline::GridFix> fix;
    if (!gps.is_none()) {
      const auto g = three_numbers(gps, "gps", "(lat, lon, sigma_m)");
      const auto p = projection.forward({g[0], g[1]});
      fix = pipeline::GridFix{p.x_m, p.y_m, g[2]};
    }
    const pipeline::GridCrop crop = pipeline::frame_crop(f, cache_->grid(), projection);
    pipeline::FrameEstimate e;
    {
      py::gil_scoped_release release;
      auto frame = std::make_shared<filter::PreparedFrame>(pipeline::prepare_volume(view, options_));
      pipeline::round_like_frame_store(*frame);
      e = localizer_->step(std::move(frame), crop, {odometry[0], odometry[1], odometry[2]}, fix);
    }
    py::dict d = pose_dict(frames_, e);
    ++frames_;
    d["final"] = final_poses();
    return d;
  }

  /// The route ends: the poses of the frames still waiting for their lag, given every frame.
  py::list finish() {
    {
      py::gil_scoped_release release;
      localizer_->finish();
    }
    return final_poses();
  }

  [[nodiscard]] py::object belief_marginal() const {
    const auto* f = localizer_->filter();
    if (!f) return py::none();
    return marginal_array(f->belief());
  }

  [[nodiscard]] py::tuple window_origin() const {
    return py::make_tuple(localizer_->window().origin_u(), localizer_->window().origin_v());
  }

  [[nodiscard]] py::dict config() const { return config_dict(localizer_->config()); }
  [[nodiscard]] int lag() const { return localizer_->lag(); }

 private:
  // The estimates that became final, as pose dicts with their frame's index.
  py::list final_poses() {
    py::list out;
    for (const auto& [index, e] : localizer_->take_final()) out.append(pose_dict(static_cast<long>(index), e));
    return out;
  }

  py::dict pose_dict(long index, const pipeline::FrameEstimate& e) const {
    io::RouteFrame f;
    f.frame = std::to_string(index);
    const io::FramePose pose = pipeline::frame_pose(f, e, cache_->metadata().projection());
    py::dict d;
    d["frame"] = index;
    d["lat"] = pose.lat_deg;
    d["lon"] = pose.lon_deg;
    d["heading_deg"] = pose.compass_heading_deg;
    d["x"] = pose.x_m;
    d["y"] = pose.y_m;
    d["grid_heading_deg"] = pose.grid_heading_deg;
    d["entropy"] = pose.entropy;
    d["etu_weight"] = pose.etu_weight;
    d["volume_power"] = pose.volume_power;
    d["relocalized"] = pose.relocalized;
    return d;
  }

  std::unique_ptr<raster::CacheReader> cache_;
  pipeline::LocalizeOptions options_;
  std::unique_ptr<pipeline::SequentialLocalizer> localizer_;
  long frames_ = 0;
};

// seqloc's errors as Python exceptions, by category, in this one place: seqloc.Error is the base;
// seqloc.UsageError and seqloc.DataError are ValueErrors, seqloc.IOError an OSError,
// seqloc.InternalError a RuntimeError. The classes of the earlier module stay, under them:
// seqloc.CacheError (an OSError), seqloc.FilterError (a DataError) and seqloc.RequestError (a
// UsageError, for a crop that cannot be placed).
void register_errors(py::module_& m) {
  // Each class lives as long as the module (released: never decremented after the interpreter ends).
  const auto make = [&m](const char* name, py::handle bases, const char* doc) {
    py::object type = py::reinterpret_steal<py::object>(
        PyErr_NewExceptionWithDoc((std::string("seqloc.") + name).c_str(), doc, bases.ptr(), nullptr));
    if (!type) throw py::error_already_set();
    m.attr(name) = type;
    return type;
  };
  static const py::handle error = make("Error", PyExc_Exception, "Base of every error seqloc raises.").release();
  static const py::handle usage = make("UsageError", py::make_tuple(error, py::handle(PyExc_ValueError)),
                                       "A request that cannot be carried out as given.")
                                      .release();
  static const py::handle data =
      make("DataError", py::make_tuple(error, py::handle(PyExc_ValueError)), "Input data that cannot be used.")
          .release();
  static const py::handle io = make("IOError", py::make_tuple(error, py::handle(PyExc_OSError)),
                                    "A file that cannot be opened, read or written.")
                                   .release();
  static const py::handle internal = make("InternalError", py::make_tuple(error, py::handle(PyExc_RuntimeError)),
                                          "A broken invariant of seqloc itself.")
                                         .release();
  static const py::handle cache =
      make("CacheError", py::make_tuple(error, py::handle(PyExc_OSError)), "A region cache that cannot be read.")
          .release();
  static const py::handle filter_error = make("FilterError", data, "A frame volume the filter cannot use.").release();
  static const py::handle request = make("RequestError", usage, "A crop that cannot be placed as asked.").release();
  py::register_exception_translator([](std::exception_ptr p) {
    if (!p) return;
    try {
      std::rethrow_exception(p);
    } catch (const raster::CacheError& e) {
      PyErr_SetString(cache.ptr(), e.what());
    } catch (const raster::CropError& e) {
      PyErr_SetString(request.ptr(), e.what());
    } catch (const filter::FilterError& e) {
      PyErr_SetString(e.category() == seqloc::ErrorCategory::usage ? usage.ptr() : filter_error.ptr(), e.what());
    } catch (const seqloc::Error& e) {
      switch (e.category()) {
        case seqloc::ErrorCategory::usage:
          PyErr_SetString(usage.ptr(), e.what());
          break;
        case seqloc::ErrorCategory::data:
          PyErr_SetString(data.ptr(), e.what());
          break;
        case seqloc::ErrorCategory::io:
          PyErr_SetString(io.ptr(), e.what());
          break;
        case seqloc::ErrorCategory::internal:
          PyErr_SetString(internal.ptr(), e.what());
          break;
      }
    }
  });
}

}  // namespace

PYBIND11_MODULE(seqloc, m) {
  m.doc() = "seqloc: region caches (map crops, road distance and road prior) and the SeqLoc filter";
  m.attr("__version__") = SEQLOC_VERSION;
  register_errors(m);

  py::class_<PyCache>(m, "Cache", "A region cache (GeoPackage) opened read-only")
      .def(py::init<const std::string&, std::size_t>(), py::arg("path"), py::arg("lru_tiles") = 64)
      .def("crop", &PyCache::crop, py::arg("lat") = py::none(), py::arg("lon") = py::none(), py::arg("size_m") = 128.0,
           py::arg("layers") = std::vector<std::string>{"classes", "road_distance", "road_prior"},
           py::arg("prior_sigma_m") = filter::FilterConfig{}.mgr_sigma_m, py::arg("max_size_m") = raster::kDefaultMaxCropM,
           py::kw_only(), py::arg("x") = py::none(), py::arg("y") = py::none(),
           "North-up crop in region-grid cells (conventions.md section 4: crop_x, crop_y) around a WGS84 point "
           "(lat, lon) or a region point in metres (x=, y=)")
      .def("to_grid", &PyCache::to_grid, py::arg("lat"), py::arg("lon"), "(x, y) in the region CRS, metres")
      .def("from_grid", &PyCache::from_grid, py::arg("x"), py::arg("y"), "(lat, lon) of a region point (to_grid's inverse)")
      .def_property_readonly("info", &PyCache::info);

  py::class_<PyFilter>(m, "Filter", "The SeqLoc filter over a window of cells (docs/filter.md)")
      .def(py::init<const py::dict&>(), py::arg("config") = py::dict(),
           "config: any of the settings of Filter.settings() by name; the others keep their defaults ({\"preset\": \"paper\"} starts from the seed paper's configuration)")
      .def_static("settings", &filter_settings, "Every filter setting: {name: (default, what it is)}")
      .def_property_readonly("config", [](const PyFilter& f) { return config_dict(f.config()); },
                             "The settings in use, by name")
      .def("reset", &PyFilter::reset, py::arg("gps") = py::none(),
           "Start a sequence: uniform belief, or gps=(u, v, sigma_m) in window cells")
      .def("step", &PyFilter::step, py::arg("log_volume"), py::arg("odometry") = py::make_tuple(0.0, 0.0, 0.0),
           py::arg("crop_pose") = py::none(), py::arg("road_distance") = py::none(),
           py::arg("probabilities") = false, py::arg("cell_m") = 0.5,
           "One frame: log_volume (H, W, N) float32/float16 (NumPy, DLPack such as a CPU torch tensor, or "
           "__array__; read in place when C-contiguous), odometry (forward_m, left_m, yaw_deg), crop_pose "
           "(centre_u, centre_v, rotation_deg) in window cells (default: the window's centre, north-up), "
           "road_distance (height, width) metres for MGR. Returns the pose and diagnostics.")
      .def("recentre", &PyFilter::recentre, py::arg("du"), py::arg("dv"), "Move the window by whole cells")
      .def("belief_marginal", &PyFilter::belief_marginal,
           "The belief summed over headings: (height, width) float32, a probability per window cell");

  py::class_<PyLocalizer>(m, "Localizer",
                          "seqloc localize's seqloc (or online) mode one frame at a time over a region cache: it "
                          "owns the window, its road distances and re-centring (docs/python.md)")
      .def(py::init<const std::string&, const py::dict&, const std::string&, double, double,
                    const std::optional<std::string>&, int>(),
           py::arg("cache"), py::arg("config") = py::dict(), py::arg("mode") = "seqloc",
           py::arg("volume_temperature") = pipeline::LocalizeOptions{}.volume_temperature,
           py::arg("recentre_margin") = pipeline::LocalizeOptions{}.recentre_margin,
           py::arg("calibration") = py::none(), py::arg("lag") = 0,
           "cache: a region cache; config: filter settings by name (Filter.settings()); mode: 'seqloc' or 'online'; "
           "calibration: a calibration.json from seqloc calibrate (its temperature replaces volume_temperature); "
           "lag: fixed-lag smoothing, each frame's final pose given the `lag` frames after it too (step()'s "
           "'final', then finish())")
      .def("step", &PyLocalizer::step, py::arg("log_volume"), py::arg("odometry") = py::make_tuple(0.0, 0.0, 0.0),
           py::kw_only(), py::arg("crop_lat") = py::none(), py::arg("crop_lon") = py::none(),
           py::arg("crop_x") = py::none(), py::arg("crop_y") = py::none(), py::arg("gps") = py::none(),
           py::arg("probabilities") = false, py::arg("cell_m") = 0.5,
           "One frame: its (H, W, N) volume (NumPy, DLPack such as a CPU torch tensor, or __array__), the "
           "odometry since the last frame (forward_m, left_m, yaw_deg), the crop's centre (crop_lat/crop_lon, "
           "north-up at true north, or crop_x/crop_y in region metres, grid north), optionally gps=(lat, lon, "
           "sigma_m). Returns the frame's filtered pose: frame (its index from 0), lat, lon, heading_deg (compass), "
           "x, y (region metres), grid_heading_deg, entropy, etu_weight, volume_power, relocalized; and 'final', "
           "the poses that became final with this frame (each such a dict): this frame's with lag 0, frame "
           "index - lag's smoothed one with a lag.")
      .def("finish", &PyLocalizer::finish,
           "The route ends: the smoothed poses of the frames still waiting for their lag (given every frame)")
      .def_property_readonly("lag", &PyLocalizer::lag, "The fixed lag, frames")
      .def("belief_marginal", &PyLocalizer::belief_marginal,
           "The belief summed over headings, (height, width) float32 (None before the first frame)")
      .def_property_readonly("window_origin", &PyLocalizer::window_origin,
                             "Region pixel (u, v) of the window's cell (0, 0)")
      .def_property_readonly("config", &PyLocalizer::config, "The filter settings in use, by name");
}
