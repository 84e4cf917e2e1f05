// The arguments every binding reads, and the helpers of the typed results (bindings.hpp).

#include "bindings.hpp"

namespace seqloc::python {

py::handle usage_type_error_class, usage_key_error_class, usage_index_error_class;

void raise_as(py::handle type, const std::string& message) {
  PyErr_SetString(type.ptr(), message.c_str());
  throw py::error_already_set();
}

void usage_type_error(const std::string& message) { raise_as(usage_type_error_class, message); }

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

PointArgument point_argument(const py::object& lat, const py::object& lon, const py::object& x, const py::object& y,
                             const char* message) {
  const bool geo = !lat.is_none() || !lon.is_none(), metres = !x.is_none() || !y.is_none();
  if (geo == metres || (geo && (lat.is_none() || lon.is_none())) || (metres && (x.is_none() || y.is_none()))) {
    usage_type_error(message);
  }
  return geo ? PointArgument{true, lat.cast<double>(), lon.cast<double>()}
             : PointArgument{false, x.cast<double>(), y.cast<double>()};
}

/// A cache's path as Crop.cache_path holds it and Localizer.step(crop=) compares it: absolute and
/// normalized, computed once per opened cache.
std::string cache_identity(const raster::CacheReader& cache) {
  return std::filesystem::absolute(cache.path()).lexically_normal().string();
}

std::string number_text(double v) {
  std::ostringstream s;
  s << std::setprecision(10) << v;
  return s.str();
}

}  // namespace seqloc::python
