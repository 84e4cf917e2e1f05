#pragma once
// What the files of seqloc._seqloc share (python/module.cpp is the module itself; each other file
// binds one concern: errors.cpp the exception classes, cache.cpp region caches and their crops,
// filter.cpp the filter, routes.cpp route and run folders and their poses, localizer.cpp the
// localizer): the arguments every binding reads, the typed results, a route's frame.

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

namespace seqloc::python {

namespace py = pybind11;

// ---- Arguments.

// Usage errors that are also the builtin a Python user catches for them (seqloc.UsageTypeError is a
// seqloc.UsageError and a TypeError, ...); register_errors makes the classes.
extern py::handle usage_type_error_class, usage_key_error_class, usage_index_error_class;

[[noreturn]] void raise_as(py::handle type, const std::string& message);
[[noreturn]] void usage_type_error(const std::string& message);

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
py::array as_array(const py::object& value, const char* name);

/// Three numbers from any sequence of them; a short TypeError naming the argument otherwise.
std::array<double, 3> three_numbers(const py::object& value, const char* name, const char* what);

/// A point given either as (lat, lon) or as region metres (x, y), exactly one pair of the two.
struct PointArgument {
  bool geo = false;
  double a = 0, b = 0;  ///< lat, lon or x, y
};
PointArgument point_argument(const py::object& lat, const py::object& lon, const py::object& x, const py::object& y,
                             const char* message);

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

/// A cache's path as Crop.cache_path holds it and Localizer.step(crop=) compares it: absolute and
/// normalized, computed once per opened cache.
std::string cache_identity(const raster::CacheReader& cache);

/// A number as the results' __repr__ print it (10 significant digits).
std::string number_text(double v);

// ---- The filter's settings and volumes (filter.cpp), which the localizer reads too.

// The filter's settings by name, from filter::filter_config_fields (the one list of them).
filter::FilterConfig config_from(const py::dict& d);
py::dict config_dict(const filter::FilterConfig& c);
/// A belief's position marginal as a (height, width) float32 array.
py::array_t<float> marginal_array(const filter::BeliefVolume& belief);
/// A volume argument as the filter reads it: (H, W, N) float32 or float16, C order, kept alive by
/// `holder`.
filter::FrameVolume volume_view(const py::object& value, bool probabilities, double cell_m, py::array& holder);

// ---- A route's frame (routes.cpp binds it; the localizer steps it).

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

// ---- The bindings, one concern a file; PYBIND11_MODULE (module.cpp) calls them in this order.

void register_errors(py::module_& m);
void bind_map_results(py::module_& m);
void bind_filter_results(py::module_& m);
void bind_poses(py::module_& m);
void bind_routes(py::module_& m);
void bind_run_folder(py::module_& m);
void bind_cache(py::module_& m);
void bind_filter(py::module_& m);
void bind_localizer(py::module_& m);

}  // namespace seqloc::python
