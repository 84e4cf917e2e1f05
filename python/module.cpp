// seqloc._seqloc, the compiled part of the `seqloc` Python package (docs/python.md): region
// caches, route and run folders, the SeqLoc filter and localize's localizer for Python tools, e.g.
// a PyTorch loop that feeds a backbone the map crop around a GPS fix and runs SeqLoc online on its
// output. Results are typed objects (python/seqloc/_seqloc.pyi lists them); arrays come back as
// NumPy arrays that own the C++ buffers (no copies); volumes go in as arrays read in place.

#include <algorithm>
#include <array>
#include <cstring>
#include <deque>
#include <filesystem>
#include <iomanip>
#include <map>
#include <memory>
#include <optional>
#include <span>
#include <sstream>
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
#include "seqloc/gpu/device_filter.hpp"
#include "seqloc/io/npy.hpp"
#include "seqloc/io/results.hpp"
#include "seqloc/io/route.hpp"
#include "seqloc/io/run_folder.hpp"
#include "seqloc/pipeline/backbone_calibration.hpp"
#include "seqloc/pipeline/frame_store.hpp"
#include "seqloc/pipeline/localize.hpp"
#include "seqloc/pipeline/modes.hpp"
#include "seqloc/pipeline/sequential_localizer.hpp"
#include "seqloc/raster/cache.hpp"
#include "seqloc/raster/crop_window.hpp"
#include "seqloc/ros/route_bag.hpp"

namespace py = pybind11;
namespace filter = seqloc::filter;
namespace io = seqloc::io;
namespace osm = seqloc::osm;
namespace pipeline = seqloc::pipeline;
namespace raster = seqloc::raster;

namespace {

// Usage errors that are also the builtin a Python user catches for them (seqloc.UsageTypeError is a
// seqloc.UsageError and a TypeError, ...); register_errors makes the classes.
py::handle usage_type_error_class, usage_key_error_class, usage_index_error_class;

[[noreturn]] void raise_as(py::handle type, const std::string& message) {
  PyErr_SetString(type.ptr(), message.c_str());
  throw py::error_already_set();
}
[[noreturn]] void usage_type_error(const std::string& message) { raise_as(usage_type_error_class, message); }

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
    usage_type_error(std::string(name) + ": cannot read a " +
                     std::string(py::str(py::type::of(value).attr("__name__"))) + " as an array in memory (" +
                     std::string(py::str(e.value())).substr(0, 200) + ")");
  }
  usage_type_error(std::string(name) + ": expected an array (NumPy, DLPack or __array__), got " +
                   std::string(py::str(py::type::of(value).attr("__name__"))));
}

/// Three numbers from any sequence of them; a short TypeError naming the argument otherwise.
std::array<double, 3> three_numbers(const py::object& value, const char* name, const char* what) {
  try {
    const auto t = value.cast<std::tuple<double, double, double>>();
    return {std::get<0>(t), std::get<1>(t), std::get<2>(t)};
  } catch (const py::cast_error&) {
    usage_type_error(std::string(name) + ": expected three numbers " + what + ", got a " +
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
    usage_type_error(message);
  }
  return geo ? PointArgument{true, lat.cast<double>(), lon.cast<double>()}
             : PointArgument{false, x.cast<double>(), y.cast<double>()};
}

// ---- The typed results: plain objects with attributes, each name with one meaning (compass
// headings as heading_deg, grid values named as such), bound read-only.

/// A map crop (Cache.crop).
struct Crop {
  py::object classes = py::none(), road_distance = py::none(), road_prior = py::none();
  double crop_x = 0, crop_y = 0, cell_m = raster::kCellM;
  py::tuple geotransform;
  std::string crs_wkt;
  std::string cache_path;  ///< the cache it was cut from (Localizer.step(crop=) checks it)
};

/// What a cache holds (Cache.info).
struct CacheInfo {
  std::string path, source_file, crs_wkt;
  double centre_lat = 0, centre_lon = 0, max_distance_m = 0;
  std::pair<int, int> tiles;
  std::array<double, 4> extent{};
};

/// A pose in a filter's window: cells and the grid heading (clockwise from the window's up, grid
/// north).
struct WindowPose {
  double u = 0, v = 0, grid_heading_deg = 0;
};

/// One Filter.step.
struct FilterResult {
  WindowPose pose, argmax;
  double frame_entropy = 0, etu_weight = 1, volume_power = 1, peak_log_belief = 0;
  bool relocalized = false;
};

/// A pose of a route's frame: the Localizer's, or a run folder's poses.csv row.
struct Pose {
  long index = 0;  ///< the frame's place in the route, from 0
  io::FramePose pose;
  bool grid_heading_known = true;  ///< poses.csv does not hold the grid heading
};

/// A run's metrics for one mode (conventions.md section 7).
struct Metrics {
  io::Metrics m;
};

Pose make_pose(long index, const pipeline::FrameEstimate& e, const io::RouteFrame& f,
               const osm::RegionProjection& projection) {
  return {index, pipeline::frame_pose(f, e, projection), true};
}

std::optional<double> known(bool is, double value) { return is ? std::optional<double>(value) : std::nullopt; }

/// A cache's path as Crop.cache_path holds it and Localizer.step(crop=) compares it: absolute and
/// normalized, computed once per opened cache.
std::string cache_identity(const raster::CacheReader& cache) {
  return std::filesystem::absolute(cache.path()).lexically_normal().string();
}

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

// The filter's settings by name, from filter::filter_config_fields (the one list of them).
filter::FilterConfig config_from(const py::dict& d) {
  // "preset": "paper" starts from the seed paper's configuration; the other keys override it.
  filter::FilterConfig c;
  if (d.contains("preset")) {
    const auto preset = d["preset"].cast<std::string>();
    if (preset != "paper") throw seqloc::UsageError("preset '" + preset + "': the one preset is 'paper'");
    c = filter::paper_config();
  }
  const auto fields = filter::filter_config_fields();
  for (const auto& item : d) {
    const auto key = item.first.cast<std::string>();
    if (key == "preset") continue;
    const py::handle value = item.second;
    const auto field = std::find_if(fields.begin(), fields.end(), [&](const auto& f) { return key == f.name; });
    if (field == fields.end())
      raise_as(usage_key_error_class, "unknown filter setting '" + key + "' (Filter.settings() lists them)");
    std::visit([&](auto member) { c.*member = value.cast<std::remove_reference_t<decltype(c.*member)>>(); },
               field->member);
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

/// A belief's position marginal as a (height, width) float32 array.
py::array_t<float> marginal_array(const filter::BeliefVolume& belief) {
  return adopt(belief.position_marginal(), {belief.height(), belief.width()});
}

/// A volume argument as the filter reads it: (H, W, N) float32 or float16, C order, kept alive by
/// `holder`.
filter::FrameVolume volume_view(const py::object& value, bool probabilities, double cell_m, py::array& holder) {
  const py::array volume = as_array(value, "log_volume");
  if (volume.ndim() != 3) {
    throw seqloc::UsageError("log_volume: expected shape (H, W, N), got " + std::to_string(volume.ndim()) +
                             " dimensions");
  }
  filter::FrameVolume view;
  if (py::isinstance<py::array_t<float>>(volume)) {
    holder = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(volume);
    view.type = filter::VolumeType::float32;
  } else if (volume.dtype().kind() == 'f' && volume.dtype().itemsize() == 2) {
    holder = py::array::ensure(volume, py::array::c_style);
    view.type = filter::VolumeType::float16;
  } else {
    throw seqloc::UsageError("log_volume: expected float32 or float16, got dtype " +
                             std::string(py::str(volume.dtype())));
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
      const auto t = three_numbers(gps, "gps", "(u, v, sigma_m)");
      filter_.reset_gaussian(t[0], t[1], t[2]);
    }
  }

  FilterResult step(const py::object& volume_in, const py::object& odometry_in, const py::object& crop_pose_in,
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
      distance = py::array_t<float, py::array::c_style | py::array::forcecast>::ensure(
          as_array(road_distance, "road_distance"));
      if (!distance || distance.ndim() != 2 || distance.shape(0) != c.height || distance.shape(1) != c.width) {
        throw seqloc::UsageError("road_distance: expected a (" + std::to_string(c.height) + ", " +
                                 std::to_string(c.width) + ") float array, the window's size");
      }
      distance_window = {distance.data(), static_cast<std::size_t>(distance.size())};
    } else if (c.mgr) {
      throw seqloc::UsageError("road_distance: MGR is on and needs the window's road distance (or set mgr=False)");
    }
    filter::FrameResult r;
    {
      py::gil_scoped_release release;
      const auto frame = filter::prepare_frame(view, c.headings, c.threads);
      r = filter_.step(frame, crop, odo, distance_window);
    }
    const auto window_pose = [](const filter::Pose& p) { return WindowPose{p.u, p.v, p.heading_deg}; };
    return {window_pose(r.pose), window_pose(r.argmax), r.frame_entropy, r.etu_weight,
            r.volume_power,      r.peak_log_belief,     r.relocalized};
  }

  void recentre(int du, int dv) { filter_.recentre(du, dv); }

  /// The belief summed over headings, (height, width) float32: a probability per window cell.
  [[nodiscard]] py::array_t<float> belief_marginal() const { return marginal_array(filter_.belief()); }

 private:
  filter::SeqLocFilter filter_;
};

// ---- Route folders and run folders, read by io's one reader of each.

/// A route folder read and checked (io::read_route), shared by its frames.
using SharedRoute = std::shared_ptr<const io::Route>;

/// One frame of a route (a frames.csv row), which knows its route.
struct RouteFrame {
  SharedRoute route;
  std::size_t index = 0;
  [[nodiscard]] const io::RouteFrame& row() const { return route->frames[index]; }
  /// The row of a frame with a volume; UsageError for one with a BEV observation.
  [[nodiscard]] const io::RouteFrame& volume_row() const {
    const io::RouteFrame& f = row();
    if (f.volume.empty()) {
      throw seqloc::UsageError(f.observation.string() + " (frames.csv line " + std::to_string(f.line) +
                               "): the frame has a BEV observation, not a volume (seqloc match scores it)");
    }
    return f;
  }

  /// The frame's volume as the filter takes it, (H, W, N), read-only and memory-mapped (no copy;
  /// an NHW route's volume is a transposed view of its file).
  [[nodiscard]] py::array read_volume() const {
    const io::RouteFrame& f = volume_row();
    auto npy = std::make_unique<io::NpyVolume>(f.volume);
    io::check_volume_layout(*route, f, *npy);
    const py::dtype dtype = npy->type() == filter::VolumeType::float16 ? py::dtype("float16") : py::dtype::of<float>();
    const std::vector<py::ssize_t> shape{npy->height(), npy->width(), npy->bins()};
    const void* data = npy->data();
    auto* owner = npy.release();
    py::capsule unmap(owner, [](void* p) { delete static_cast<io::NpyVolume*>(p); });
    py::array mapped(dtype, shape, data, unmap);
    mapped.attr("setflags")(py::arg("write") = false);
    if (route->layout == io::VolumeLayout::nhw) return mapped.attr("transpose")(1, 2, 0);
    return mapped;
  }
};

class PyRoute {
 public:
  explicit PyRoute(const std::string& path) {
    py::gil_scoped_release release;
    route_ = std::make_shared<const io::Route>(io::read_route(path));
  }
  [[nodiscard]] const io::Route& route() const { return *route_; }
  [[nodiscard]] std::size_t size() const { return route_->frames.size(); }
  [[nodiscard]] RouteFrame frame(py::ssize_t i) const {
    const auto n = static_cast<py::ssize_t>(size());
    if (i < 0) i += n;
    if (i < 0 || i >= n)
      raise_as(usage_index_error_class, "frame index out of range (the route has " + std::to_string(n) + ")");
    return {route_, static_cast<std::size_t>(i)};
  }
  [[nodiscard]] std::vector<RouteFrame> frames() const {
    std::vector<RouteFrame> out;
    for (std::size_t i = 0; i < size(); ++i) out.push_back({route_, i});
    return out;
  }

 private:
  SharedRoute route_;
};

/// The poses.csv file of a mode as poses (index: the row's place).
std::vector<Pose> poses_of(const std::vector<io::FramePose>& rows) {
  std::vector<Pose> out;
  for (std::size_t i = 0; i < rows.size(); ++i) out.push_back({static_cast<long>(i), rows[i], false});
  return out;
}

class PyRunFolder {
 public:
  explicit PyRunFolder(const std::string& path) : folder_(path) {
    std::error_code ec;
    if (!std::filesystem::is_directory(folder_.root(), ec)) throw seqloc::IoError(path + ": not a folder");
  }
  [[nodiscard]] std::string path() const { return folder_.root().string(); }

  /// The routes with results: folders holding a mode's poses.csv, sorted.
  [[nodiscard]] std::vector<std::string> routes() const {
    std::vector<std::string> out;
    std::error_code ec;
    for (const auto& entry : std::filesystem::directory_iterator(folder_.root(), ec)) {
      const std::string route = entry.path().filename().string();
      if (entry.is_directory() && !modes(route).empty()) out.push_back(route);
    }
    std::sort(out.begin(), out.end());
    return out;
  }

  /// The modes the run has for `route`, in the recall table's order.
  [[nodiscard]] std::vector<std::string> modes(const std::string& route) const {
    std::vector<std::string> out;
    std::error_code ec;
    for (const io::Mode mode : io::kModes) {
      if (std::filesystem::is_regular_file(folder_.mode_dir(route, mode) / "poses.csv", ec))
        out.emplace_back(io::mode_name(mode));
    }
    return out;
  }

  [[nodiscard]] std::vector<Pose> poses(const std::string& route, const std::string& mode_text) const {
    const auto mode = io::parse_mode(mode_text);
    if (!mode) throw seqloc::UsageError("mode '" + mode_text + "': one of single, offline, online, seqloc, smooth");
    const auto file = folder_.mode_dir(route, *mode) / "poses.csv";
    std::error_code ec;
    if (!std::filesystem::is_regular_file(file, ec)) {
      throw seqloc::DataError(file.string() + ": no poses for route '" + route + "' in mode " + mode_text);
    }
    std::vector<io::FramePose> rows;
    {
      py::gil_scoped_release release;
      rows = io::read_poses_csv(file);
    }
    return poses_of(rows);
  }

  /// The metrics per mode over every route (the recall table of seqloc evaluate).
  [[nodiscard]] std::map<std::string, Metrics> evaluate() const {
    io::MetricsByMode by_mode;
    {
      py::gil_scoped_release release;
      by_mode = io::evaluate_poses_files(io::find_poses_files({folder_.root()}));
    }
    std::map<std::string, Metrics> out;
    for (const auto& [mode, m] : by_mode) out.emplace(mode, Metrics{m});
    return out;
  }

 private:
  io::RunFolder folder_;
};

/// seqloc localize's online and seqloc modes, one frame at a time: the window over the region,
/// its road distances and re-centring, the frames prepared and rounded exactly as localize
/// prepares a route's (pipeline::SequentialLocalizer, the class localize itself drives).
class PyLocalizer {
 public:
  PyLocalizer(const std::string& cache, const py::dict& config, const std::string& mode, double volume_temperature,
              double recentre_margin, const std::optional<std::string>& calibration, int lag, const std::string& device)
      : cache_(std::make_unique<raster::CacheReader>(cache)), identity_(cache_identity(*cache_)) {
    if (lag < 0) throw seqloc::UsageError("lag: must be >= 0 frames, got " + std::to_string(lag));
    if (mode != "seqloc" && mode != "online")
      throw seqloc::UsageError("mode: 'seqloc' or 'online', got '" + mode + "'");
    const auto where = pipeline::device_from_name(device);
    if (!where) throw seqloc::UsageError("device: 'cpu', 'cuda' or 'cuda-host', got '" + device + "'");
    options_.filter = config_from(config);
    options_.volume_temperature = volume_temperature;
    options_.recentre_margin = recentre_margin;
    if (calibration) pipeline::apply_calibration_file(*calibration, options_);
    options_.validate();
    pipeline::check_device(*where, options_.filter);
    localizer_ = std::make_unique<pipeline::SequentialLocalizer>(*cache_, options_.filter, mode == "online",
                                                                 recentre_margin, lag, *where);
  }

  /// A Cache.crop given as the frame's crop: its centre in region metres, so its north is grid
  /// north, as the crop's own cells are; from this localizer's cache, and given alone.
  [[nodiscard]] PointArgument crop_argument(const py::object& crop, const py::object& crop_lat,
                                            const py::object& crop_lon, const py::object& crop_x,
                                            const py::object& crop_y) const {
    if (!crop_lat.is_none() || !crop_lon.is_none() || !crop_x.is_none() || !crop_y.is_none()) {
      usage_type_error("step: give crop= or the crop's centre (crop_lat/crop_lon, crop_x/crop_y), not both");
    }
    if (!py::isinstance<Crop>(crop)) {
      usage_type_error("crop: expected the seqloc.Crop that Cache.crop returns, got a " +
                       std::string(py::str(py::type::of(crop).attr("__name__"))));
    }
    const auto& c = crop.cast<const Crop&>();
    if (c.cache_path != identity_) {
      throw seqloc::UsageError("crop: cut from " + c.cache_path + ", not from this localizer's cache " + identity_);
    }
    return {false, c.crop_x, c.crop_y};
  }

  Pose step(const py::object& volume_in, const py::object& odometry_in, const py::object& crop_lat,
            const py::object& crop_lon, const py::object& crop_x, const py::object& crop_y, const py::object& gps,
            bool probabilities, double cell_m, const py::object& crop) {
    py::array holder;
    const filter::FrameVolume view = volume_view(volume_in, probabilities, cell_m, holder);
    const auto odometry = three_numbers(odometry_in, "odometry", "(forward_m, left_m, yaw_deg)");
    // The frame as a route row would hold it: its crop, lat/lon or region metres.
    io::RouteFrame f;
    f.frame = std::to_string(stepped());
    f.timestamp_s = static_cast<double>(stepped());
    f.odometry = {odometry[0], odometry[1], odometry[2]};
    const PointArgument centre =
        crop.is_none() ? point_argument(crop_lat, crop_lon, crop_x, crop_y,
                                        "step: give crop= (a Cache.crop), or the crop's centre as crop_lat and "
                                        "crop_lon, or as crop_x and crop_y")
                       : crop_argument(crop, crop_lat, crop_lon, crop_x, crop_y);
    if (centre.geo) {
      f.crop_geo = seqloc::osm::GeoPoint{centre.a, centre.b};
    } else {
      f.crop_grid = seqloc::osm::GridPoint{centre.a, centre.b};
    }
    if (!gps.is_none()) {
      const auto g = three_numbers(gps, "gps", "(lat, lon, sigma_m)");
      f.gps = io::GpsPrior{{g[0], g[1]}, g[2]};
    }
    py::gil_scoped_release release;
    return step_volume(view, std::move(f));
  }

  /// A route's frame as localize steps it: its volume file, crop, odometry and GPS fix.
  Pose step_frame(const RouteFrame& frame) {
    const io::RouteFrame& f = frame.volume_row();
    py::gil_scoped_release release;
    const io::NpyVolume npy(f.volume);
    std::vector<unsigned char> transposed;
    return step_volume(io::frame_volume(*frame.route, f, npy, transposed), f);
  }

  /// The poses that became final since the last call, in frame order: with a lag L, after frame
  /// t the smoothed pose of frame t - L (finish() gives the last L). Empty with lag 0, where each
  /// step's own pose is final.
  std::vector<Pose> final_poses() {
    std::vector<Pose> out;
    out.swap(final_);
    return out;
  }

  /// The route ends: the smoothed poses of the frames still waiting for their lag (and any not
  /// taken by final_poses()), given every frame.
  std::vector<Pose> finish() {
    {
      py::gil_scoped_release release;
      localizer_->finish();
      take_final();
    }
    return final_poses();
  }

  [[nodiscard]] py::object belief_marginal() const {
    const auto* f = localizer_->filter();
    if (!f) return py::none();
    return marginal_array(f->belief());
  }

  [[nodiscard]] std::pair<std::int64_t, std::int64_t> window_origin() const {
    return {localizer_->window().origin_u(), localizer_->window().origin_v()};
  }

  [[nodiscard]] py::dict config() const { return config_dict(localizer_->config()); }
  [[nodiscard]] int lag() const { return localizer_->lag(); }

 private:
  // Frames stepped so far (the next one's index).
  [[nodiscard]] std::size_t stepped() const { return taken_ + frames_.size(); }

  // The localizer's step on a volume, prepared and rounded as localize prepares a route's; `f` is
  // the frame's row (crop, odometry, GPS, and the id, time and truth its poses carry). Called
  // without the GIL.
  Pose step_volume(const filter::FrameVolume& view, io::RouteFrame f) {
    auto prepared = std::make_shared<filter::PreparedFrame>(pipeline::prepare_volume(view, options_));
    pipeline::round_like_frame_store(*prepared);
    const auto& projection = cache_->metadata().projection();
    const pipeline::GridCrop crop = pipeline::frame_crop(f, cache_->grid(), projection);
    const pipeline::FrameEstimate e =
        localizer_->step(std::move(prepared), crop, f.odometry, pipeline::frame_gps_fix(f, projection));
    Pose pose = make_pose(static_cast<long>(stepped()), e, f, projection);
    frames_.push_back(std::move(f));
    take_final();
    return pose;
  }

  // Moves the estimates that became final into final_ (lag > 0) and forgets the frames no lag
  // still needs.
  void take_final() {
    const auto& projection = cache_->metadata().projection();
    for (const auto& [index, e] : localizer_->take_final()) {
      if (localizer_->lag() > 0) {
        final_.push_back(make_pose(static_cast<long>(index), e, frames_.at(index - taken_), projection));
      }
      while (taken_ <= index) {
        frames_.pop_front();
        ++taken_;
      }
    }
  }

  std::unique_ptr<raster::CacheReader> cache_;
  std::string identity_;  ///< cache_identity(*cache_)
  pipeline::LocalizeOptions options_;
  std::unique_ptr<pipeline::SequentialLocalizer> localizer_;
  std::deque<io::RouteFrame> frames_;  ///< the frames stepped and not yet final, from frame taken_ on
  std::size_t taken_ = 0;              ///< frames final and forgotten
  std::vector<Pose> final_;            ///< poses final and not yet taken (lag > 0)
};

// seqloc's errors as Python exceptions in this one place, by their category alone: seqloc.Error is
// the base; seqloc.UsageError and seqloc.DataError are ValueErrors, seqloc.NotFoundError a
// UsageError and a LookupError, seqloc.IOError an OSError, seqloc.InternalError a RuntimeError.
// The names of the earlier module's classes stay, as the category classes they were raised for:
// seqloc.CacheError is seqloc.IOError, seqloc.FilterError seqloc.DataError and seqloc.RequestError
// seqloc.UsageError.
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
  static const py::handle not_found = make("NotFoundError", py::make_tuple(usage, py::handle(PyExc_LookupError)),
                                           "A request for what is not there: a point or tile outside the region.")
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
  m.attr("CacheError") = io;
  m.attr("FilterError") = data;
  m.attr("RequestError") = usage;
  usage_type_error_class = make("UsageTypeError", py::make_tuple(usage, py::handle(PyExc_TypeError)),
                                "An argument of a type seqloc cannot use.")
                               .release();
  usage_key_error_class = make("UsageKeyError", py::make_tuple(usage, py::handle(PyExc_KeyError)),
                               "A name seqloc does not know (a filter setting, say).")
                              .release();
  usage_index_error_class =
      make("UsageIndexError", py::make_tuple(usage, py::handle(PyExc_IndexError)), "An index outside what it indexes.")
          .release();
  py::register_exception_translator([](std::exception_ptr p) {
    if (!p) return;
    try {
      std::rethrow_exception(p);
    } catch (const seqloc::Error& e) {
      py::handle type = internal;
      switch (e.category()) {
        case seqloc::ErrorCategory::usage:
          type = usage;
          break;
        case seqloc::ErrorCategory::not_found:
          type = not_found;
          break;
        case seqloc::ErrorCategory::data:
          type = data;
          break;
        case seqloc::ErrorCategory::io:
          type = io;
          break;
        case seqloc::ErrorCategory::internal:
          break;
      }
      PyErr_SetString(type.ptr(), e.what());
    } catch (const py::error_already_set&) {
      throw;  // a Python exception already (ours, or Python's own)
    } catch (const py::builtin_exception&) {
      throw;  // pybind11's own (an argument that does not convert, StopIteration)
    } catch (const std::bad_alloc&) {
      throw;  // MemoryError
    } catch (const std::exception& e) {
      // Anything else escaping seqloc is a bug of ours, not a bare RuntimeError.
      PyErr_SetString(internal.ptr(), e.what());
    }
  });
}

// ---- The module.

std::string number_text(double v) {
  std::ostringstream s;
  s << std::setprecision(10) << v;
  return s.str();
}

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

void bind_filter_results(py::module_& m) {
  py::class_<WindowPose>(m, "WindowPose", "A pose in a filter's window: cells and the grid heading")
      .def_readonly("u", &WindowPose::u, "Window column, cells")
      .def_readonly("v", &WindowPose::v, "Window row, cells (down)")
      .def_readonly("grid_heading_deg", &WindowPose::grid_heading_deg,
                    "Degrees clockwise from the window's up (grid north), in [0, 360)")
      .def("__repr__", [](const WindowPose& p) {
        return "WindowPose(u=" + number_text(p.u) + ", v=" + number_text(p.v) +
               ", grid_heading_deg=" + number_text(p.grid_heading_deg) + ")";
      });
  py::class_<FilterResult>(m, "FilterResult", "One Filter.step: the estimate and the frame's diagnostics")
      .def_property_readonly(
          "u", [](const FilterResult& r) { return r.pose.u; }, "The estimate (PAS): window column")
      .def_property_readonly(
          "v", [](const FilterResult& r) { return r.pose.v; }, "The estimate: window row")
      .def_property_readonly(
          "grid_heading_deg", [](const FilterResult& r) { return r.pose.grid_heading_deg; },
          "The estimate's heading, clockwise from grid north")
      .def_readonly("pose", &FilterResult::pose, "The estimate as a WindowPose")
      .def_readonly("argmax", &FilterResult::argmax, "The belief's most likely cell and bin")
      .def_readonly("frame_entropy", &FilterResult::frame_entropy, "The frame volume's normalized entropy")
      .def_readonly("etu_weight", &FilterResult::etu_weight, "ETU's weight of the frame")
      .def_readonly("volume_power", &FilterResult::volume_power, "Self-calibration's power of the frame")
      .def_readonly("relocalized", &FilterResult::relocalized, "Whether MGR re-seeded the belief")
      .def_readonly("peak_log_belief", &FilterResult::peak_log_belief, "The belief's log at its argmax")
      .def("__repr__", [](const FilterResult& r) {
        return "FilterResult(u=" + number_text(r.pose.u) + ", v=" + number_text(r.pose.v) +
               ", grid_heading_deg=" + number_text(r.pose.grid_heading_deg) + ")";
      });
}

// The uncertainty of a Pose (None for modes without a belief).
void bind_pose_uncertainty(py::class_<Pose>& pose) {
  pose.def_property_readonly(
          "covariance_m2",
          [](const Pose& p) -> std::optional<std::pair<std::pair<double, double>, std::pair<double, double>>> {
            if (!p.pose.uncertainty) return std::nullopt;
            const auto& u = *p.pose.uncertainty;
            return std::pair{std::pair{u.cov_xx_m2, u.cov_xy_m2}, std::pair{u.cov_xy_m2, u.cov_yy_m2}};
          },
          "Position covariance about the pose, m^2, along the region CRS's x (east) and y (north): "
          "[[xx, xy], [xy, yy]]; None for modes without a belief (single, offline)")
      .def_property_readonly(
          "heading_sd_deg",
          [](const Pose& p) -> std::optional<double> {
            return p.pose.uncertainty ? std::optional(p.pose.uncertainty->heading_sd_deg) : std::nullopt;
          },
          "Heading standard deviation about the pose's heading, degrees")
      .def_property_readonly(
          "mass_within_5m",
          [](const Pose& p) -> std::optional<double> {
            return p.pose.uncertainty ? std::optional(p.pose.uncertainty->mass_within_5m) : std::nullopt;
          },
          "The belief's probability within 5 m of the pose")
      .def_property_readonly(
          "second_mode_share",
          [](const Pose& p) -> std::optional<double> {
            return p.pose.uncertainty ? std::optional(p.pose.uncertainty->second_mode_share) : std::nullopt;
          },
          "The probability within 5 m of a second place over 10 m away (0: none)")
      .def_property_readonly(
          "multimodal",
          [](const Pose& p) -> std::optional<bool> {
            return p.pose.uncertainty ? std::optional(p.pose.uncertainty->multimodal) : std::nullopt;
          },
          "A second place holds at least 10 % of the belief: do not fuse the pose as one Gaussian")
      .def(
          "local_frame",
          [](const Pose& p, double origin_lat_deg, double origin_lon_deg) {
            if (!p.grid_heading_known) {
              throw seqloc::UsageError("frame " + p.pose.frame +
                                       ": a pose read from poses.csv has no grid heading to turn its covariance by");
            }
            const seqloc::ros::LocalPose l = seqloc::ros::to_local_frame(p.pose, {origin_lat_deg, origin_lon_deg});
            const auto& f = l.fix_covariance;
            const auto& c = l.frame_covariance;
            py::dict d;
            d["position_m"] = py::make_tuple(l.position[0], l.position[1], l.position[2]);
            d["yaw_rad"] = l.yaw_rad;
            d["covariance_m2"] = py::make_tuple(py::make_tuple(c[0], c[1]), py::make_tuple(c[1], c[2]));
            d["fix_covariance_m2"] = py::make_tuple(py::make_tuple(f[0], f[1]), py::make_tuple(f[1], f[2]));
            return d;
          },
          py::arg("origin_lat_deg"), py::arg("origin_lon_deg"),
          "The pose as a ROS 2 bag carries it (docs/ros.md): in the east-north-up frame at the origin, "
          "position_m (x, y, z), yaw_rad (counter-clockwise from east) and covariance_m2 along the frame's "
          "axes; fix_covariance_m2 along true east and north at the pose (a NavSatFix's)");
}

void bind_poses(py::module_& m) {
  const auto optional_field = [](std::optional<double> io::FramePose::*field) {
    return [field](const Pose& p) { return p.pose.*field; };
  };
  py::class_<Pose> pose(m, "Pose", "A frame's pose: the Localizer's, or a row of a run folder's poses.csv");
  bind_pose_uncertainty(pose);
  pose.def_readonly("index", &Pose::index, "The frame's place in the route, from 0")
      .def_property_readonly(
          "frame", [](const Pose& p) { return p.pose.frame; }, "The frame's id (frames.csv)")
      .def_property_readonly("timestamp_s", [](const Pose& p) { return p.pose.timestamp_s; })
      .def_property_readonly(
          "lat", [](const Pose& p) { return p.pose.lat_deg; }, "WGS84 degrees")
      .def_property_readonly(
          "lon", [](const Pose& p) { return p.pose.lon_deg; }, "WGS84 degrees")
      .def_property_readonly(
          "heading_deg", [](const Pose& p) { return p.pose.compass_heading_deg; },
          "Compass heading: degrees clockwise from true north")
      .def_property_readonly(
          "grid_heading_deg", [](const Pose& p) { return known(p.grid_heading_known, p.pose.grid_heading_deg); },
          "Degrees clockwise from the region CRS's grid north (None for poses read from "
          "poses.csv, which holds the compass heading only)")
      .def_property_readonly(
          "x_m", [](const Pose& p) { return p.pose.x_m; }, "Region CRS metres (east)")
      .def_property_readonly(
          "y_m", [](const Pose& p) { return p.pose.y_m; }, "Region CRS metres (north)")
      .def_property_readonly(
          "entropy", [](const Pose& p) { return p.pose.entropy; }, "The frame volume's normalized entropy")
      .def_property_readonly("etu_weight", [](const Pose& p) { return p.pose.etu_weight; })
      .def_property_readonly(
          "volume_power", [](const Pose& p) { return p.pose.volume_power; },
          "Self-calibration's power of the frame (1 where it does not apply)")
      .def_property_readonly("relocalized", [](const Pose& p) { return p.pose.relocalized; })
      .def_property_readonly("position_error_m", optional_field(&io::FramePose::position_error_m),
                             "Against the frame's ground truth, or None without it")
      .def_property_readonly("heading_error_deg", optional_field(&io::FramePose::heading_error_deg))
      .def_property_readonly("lateral_error_m", optional_field(&io::FramePose::lateral_error_m))
      .def_property_readonly("longitudinal_error_m", optional_field(&io::FramePose::longitudinal_error_m))
      .def_property_readonly(
          "region", [](const Pose& p) { return p.pose.region; },
          "The region (cache file stem) whose CRS x_m and y_m are in; empty when not recorded")
      .def("__repr__", [](const Pose& p) {
        return "Pose(index=" + std::to_string(p.index) + ", frame=" + std::string(py::repr(py::str(p.pose.frame))) +
               ", lat=" + number_text(p.pose.lat_deg) + ", lon=" + number_text(p.pose.lon_deg) +
               ", heading_deg=" + number_text(p.pose.compass_heading_deg) + ")";
      });
  const auto triple = [](const double(&v)[3]) { return std::make_tuple(v[0], v[1], v[2]); };
  py::class_<Metrics>(m, "Metrics", "A mode's metrics over a run's frames with ground truth (conventions.md 7)")
      .def_property_readonly("frames", [](const Metrics& x) { return x.m.frames; })
      .def_property_readonly(
          "position_recall", [triple](const Metrics& x) { return triple(x.m.position_recall); },
          "% of frames within 1, 3 and 5 m")
      .def_property_readonly(
          "heading_recall", [triple](const Metrics& x) { return triple(x.m.heading_recall); },
          "% of frames within 1, 3 and 5 degrees")
      .def_property_readonly("mean_position_error_m", [](const Metrics& x) { return x.m.mean_position_error_m; })
      .def_property_readonly("median_position_error_m", [](const Metrics& x) { return x.m.median_position_error_m; })
      .def_property_readonly("mean_heading_error_deg", [](const Metrics& x) { return x.m.mean_heading_error_deg; })
      .def_property_readonly("median_heading_error_deg", [](const Metrics& x) { return x.m.median_heading_error_deg; })
      .def_property_readonly("mean_abs_lateral_m", [](const Metrics& x) { return x.m.mean_abs_lateral_m; })
      .def_property_readonly("mean_abs_longitudinal_m", [](const Metrics& x) { return x.m.mean_abs_longitudinal_m; });
}

void bind_routes(py::module_& m) {
  const auto optional_geo = [](bool lat) {
    return [lat](const RouteFrame& f) -> std::optional<double> {
      const auto& g = f.row().crop_geo;
      if (!g) return std::nullopt;
      return lat ? g->lat_deg : g->lon_deg;
    };
  };
  const auto optional_grid = [](bool x) {
    return [x](const RouteFrame& f) -> std::optional<double> {
      const auto& g = f.row().crop_grid;
      if (!g) return std::nullopt;
      return x ? g->x_m : g->y_m;
    };
  };
  py::class_<RouteFrame>(m, "RouteFrame", "One frame of a route folder (a frames.csv row)")
      .def_readonly("index", &RouteFrame::index, "The frame's place in the route, from 0")
      .def_property_readonly(
          "frame", [](const RouteFrame& f) { return f.row().frame; }, "The frame's id")
      .def_property_readonly(
          "line", [](const RouteFrame& f) { return f.row().line; }, "Its line in frames.csv")
      .def_property_readonly("timestamp_s", [](const RouteFrame& f) { return f.row().timestamp_s; })
      .def_property_readonly(
          "volume_path",
          [](const RouteFrame& f) -> std::optional<std::string> {
            if (f.row().volume.empty()) return std::nullopt;
            return f.row().volume.string();
          },
          "The volume's .npy file (absolute), or None for a frame with a BEV observation")
      .def_property_readonly(
          "odometry",
          [](const RouteFrame& f) {
            const auto& o = f.row().odometry;
            return std::make_tuple(o.forward_m, o.left_m, o.yaw_deg);
          },
          "(forward_m, left_m, yaw_deg) since the previous frame")
      .def_property_readonly("crop_lat", optional_geo(true), "The crop's centre (WGS84), or None")
      .def_property_readonly("crop_lon", optional_geo(false))
      .def_property_readonly("crop_x", optional_grid(true), "Or the crop's centre in region metres, or None")
      .def_property_readonly("crop_y", optional_grid(false))
      .def_property_readonly(
          "gps",
          [](const RouteFrame& f) -> std::optional<std::tuple<double, double, double>> {
            const auto& g = f.row().gps;
            if (!g) return std::nullopt;
            return std::make_tuple(g->where.lat_deg, g->where.lon_deg, g->sigma_m);
          },
          "(lat, lon, sigma_m), or None")
      .def_property_readonly(
          "truth",
          [](const RouteFrame& f) -> std::optional<std::tuple<double, double, std::optional<double>>> {
            const auto& t = f.row().truth;
            if (!t) return std::nullopt;
            return std::make_tuple(t->where.lat_deg, t->where.lon_deg, t->heading_deg);
          },
          "The ground truth (lat, lon, heading_deg compass or None), or None")
      .def("read_volume", &RouteFrame::read_volume,
           "The frame's volume as the filter takes it, (H, W, N) float32 or float16: read-only and memory-mapped")
      .def("__repr__", [](const RouteFrame& f) {
        return "RouteFrame(index=" + std::to_string(f.index) +
               ", frame=" + std::string(py::repr(py::str(f.row().frame))) + ")";
      });
  py::class_<PyRoute>(m, "Route", "A route folder (route.json, frames.csv; docs/route-format.md), read and checked")
      .def(py::init<const std::string&>(), py::arg("path"))
      .def_property_readonly("name", [](const PyRoute& r) { return r.route().name; })
      .def_property_readonly("path", [](const PyRoute& r) { return r.route().dir.string(); })
      .def_property_readonly(
          "cell_m", [](const PyRoute& r) { return r.route().cell_m; }, "Metres per volume cell")
      .def_property_readonly(
          "probabilities", [](const PyRoute& r) { return r.route().volume_kind == filter::VolumeValues::prob; },
          "Whether the volumes hold probabilities (else log-probabilities)")
      .def_property_readonly(
          "layout", [](const PyRoute& r) { return r.route().layout == io::VolumeLayout::nhw ? "NHW" : "HWN"; },
          "The volume files' axis order (read_volume gives (H, W, N) either way)")
      .def_property_readonly("frames", &PyRoute::frames)
      .def("__len__", &PyRoute::size)
      .def("__getitem__", &PyRoute::frame, py::arg("index"))
      .def("__iter__", [](const PyRoute& r) { return py::iter(py::cast(r.frames())); });
}

void bind_run_folder(py::module_& m) {
  py::class_<PyRunFolder>(m, "RunFolder", "The output folder of seqloc localize (docs/localize.md), read back")
      .def(py::init<const std::string&>(), py::arg("path"))
      .def_property_readonly("path", &PyRunFolder::path)
      .def("routes", &PyRunFolder::routes, "The routes with results, sorted")
      .def("modes", &PyRunFolder::modes, py::arg("route"), "The modes the run has for the route")
      .def("poses", &PyRunFolder::poses, py::arg("route"), py::arg("mode") = "seqloc",
           "The poses of a route in a mode (grid_heading_deg is None: poses.csv holds compass headings)")
      .def("evaluate", &PyRunFolder::evaluate, "{mode: Metrics} over every route (seqloc evaluate's table)");
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

void bind_filter(py::module_& m) {
  py::class_<PyFilter>(m, "Filter", "The SeqLoc filter over a window of cells (docs/filter.md)")
      .def(py::init<const py::dict&>(), py::arg("config") = py::dict(),
           "config: any of the settings of Filter.settings() by name; the others keep their defaults ({\"preset\": "
           "\"paper\"} starts from the seed paper's configuration)")
      .def_static("settings", &filter_settings, "Every filter setting: {name: (default, what it is)}")
      .def_property_readonly(
          "config", [](const PyFilter& f) { return config_dict(f.config()); }, "The settings in use, by name")
      .def("reset", &PyFilter::reset, py::arg("gps") = py::none(),
           "Start a sequence: uniform belief, or gps=(u, v, sigma_m) in window cells")
      .def("step", &PyFilter::step, py::arg("log_volume"), py::arg("odometry") = py::make_tuple(0.0, 0.0, 0.0),
           py::arg("crop_pose") = py::none(), py::arg("road_distance") = py::none(), py::arg("probabilities") = false,
           py::arg("cell_m") = raster::kCellM,
           "One frame: log_volume (H, W, N) float32/float16 (NumPy, DLPack such as a CPU torch tensor, or "
           "__array__; read in place when C-contiguous), odometry (forward_m, left_m, yaw_deg), crop_pose "
           "(centre_u, centre_v, rotation_deg) in window cells (default: the window's centre, north-up), "
           "road_distance (height, width) metres for MGR. Returns a FilterResult: the estimate in window cells "
           "with its grid heading, and the frame's diagnostics.")
      .def("recentre", &PyFilter::recentre, py::arg("du"), py::arg("dv"), "Move the window by whole cells")
      .def("belief_marginal", &PyFilter::belief_marginal,
           "The belief summed over headings: (height, width) float32, a probability per window cell");
}

void bind_localizer(py::module_& m) {
  py::class_<PyLocalizer>(m, "Localizer",
                          "seqloc localize's seqloc (or online) mode one frame at a time over a region cache: it "
                          "owns the window, its road distances and re-centring (docs/python.md)")
      .def(py::init<const std::string&, const py::dict&, const std::string&, double, double,
                    const std::optional<std::string>&, int, const std::string&>(),
           py::arg("cache"), py::arg("config") = py::dict(), py::arg("mode") = "seqloc",
           py::arg("volume_temperature") = pipeline::LocalizeOptions{}.volume_temperature,
           py::arg("recentre_margin") = pipeline::LocalizeOptions{}.recentre_margin,
           py::arg("calibration") = py::none(), py::arg("lag") = 0, py::kw_only(), py::arg("device") = "cpu",
           "cache: a region cache; config: filter settings by name (Filter.settings()); mode: 'seqloc' or 'online'; "
           "calibration: a calibration.json from seqloc calibrate (its temperature replaces volume_temperature); "
           "lag: fixed-lag smoothing, each frame's final pose given the `lag` frames after it too "
           "(final_poses(), then finish()); device: where the filter runs, 'cpu', 'cuda' (the GPU; seqloc.IOError "
           "saying why where none is usable) or 'cuda-host' (the CUDA kernels on the CPU, for checking): "
           "docs/gpu.md")
      .def("step", &PyLocalizer::step, py::arg("log_volume"), py::arg("odometry") = py::make_tuple(0.0, 0.0, 0.0),
           py::kw_only(), py::arg("crop_lat") = py::none(), py::arg("crop_lon") = py::none(),
           py::arg("crop_x") = py::none(), py::arg("crop_y") = py::none(), py::arg("gps") = py::none(),
           py::arg("probabilities") = false, py::arg("cell_m") = raster::kCellM, py::arg("crop") = py::none(),
           "One frame: its (H, W, N) volume (NumPy, DLPack such as a CPU torch tensor, or __array__), the "
           "odometry since the last frame (forward_m, left_m, yaw_deg), and where the volume lies: crop= the "
           "Cache.crop the backbone matched against (grid north, as its cells), or the crop's centre "
           "(crop_lat/crop_lon, north-up at true north, or crop_x/crop_y in region metres, grid north); "
           "optionally gps=(lat, lon, sigma_m). Returns the frame's filtered Pose (index and frame: its place "
           "from 0).")
      .def("step_frame", &PyLocalizer::step_frame, py::arg("frame"),
           "One frame of a Route exactly as seqloc localize steps it: its volume file, crop, odometry and GPS "
           "fix. Returns the frame's filtered Pose, with its id, time and (given ground truth) errors.")
      .def("final_poses", &PyLocalizer::final_poses,
           "With a lag L: the smoothed Poses that became final since the last call (after frame t, frame t - L's). "
           "Empty with lag 0, where each step's Pose is final.")
      .def("finish", &PyLocalizer::finish,
           "The route ends: the smoothed Poses of the frames still waiting for their lag, given every frame, "
           "after those final_poses() did not take")
      .def_property_readonly("lag", &PyLocalizer::lag, "The fixed lag, frames")
      .def("belief_marginal", &PyLocalizer::belief_marginal,
           "The belief summed over headings, (height, width) float32 (None before the first frame)")
      .def_property_readonly("window_origin", &PyLocalizer::window_origin,
                             "Region pixel (u, v) of the window's cell (0, 0)")
      .def_property_readonly("config", &PyLocalizer::config, "The filter settings in use, by name");
}

}  // namespace

PYBIND11_MODULE(_seqloc, m) {
  m.doc() = "seqloc's compiled part: region caches, route and run folders, the SeqLoc filter and localizer";
  m.attr("__version__") = SEQLOC_VERSION;
  register_errors(m);
  bind_map_results(m);
  bind_filter_results(m);
  bind_poses(m);
  bind_routes(m);
  bind_run_folder(m);
  bind_cache(m);
  bind_filter(m);
  bind_localizer(m);
  m.def(
      "cuda_status",
      [] {
        const seqloc::gpu::CudaStatus s = seqloc::gpu::cuda_status();
        py::dict d;
        d["built"] = seqloc::gpu::built_with_cuda();
        d["usable"] = s.usable;
        d["reason"] = s.reason;
        d["device"] = s.device_name;
        return d;
      },
      "Whether the filter's CUDA backend can run here (Localizer(device='cuda')): {'built': built with CUDA, "
      "'usable': a GPU it can use, 'reason': why not, 'device': the GPU's name}");
}
