// The SeqLoc filter over a window of cells (seqloc.Filter, seqloc.FilterResult, seqloc.WindowPose).

#include "bindings.hpp"

namespace seqloc::python {
namespace {

// Every setting with its default and what it is: {name: (default, help)}.
py::dict filter_settings() {
  const filter::FilterConfig defaults;
  py::dict d;
  for (const auto& field : filter::filter_config_fields()) {
    std::visit([&](auto member) { d[field.name] = py::make_tuple(defaults.*member, field.help); }, field.member);
  }
  return d;
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

}  // namespace

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

}  // namespace seqloc::python
