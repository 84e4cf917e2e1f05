// Route folders and run folders, read by io's one reader of each (seqloc.Route, seqloc.RouteFrame,
// seqloc.RunFolder), and the poses and metrics they hold (seqloc.Pose, seqloc.Metrics).

#include "bindings.hpp"

namespace seqloc::python {
namespace {

std::optional<double> known(bool is, double value) { return is ? std::optional<double>(value) : std::nullopt; }

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

}  // namespace

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

}  // namespace seqloc::python
