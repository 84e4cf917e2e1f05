// seqloc localize's localizer one frame at a time (seqloc.Localizer).

#include "bindings.hpp"

namespace seqloc::python {
namespace {

Pose make_pose(long index, const pipeline::FrameEstimate& e, const io::RouteFrame& f,
               const osm::RegionProjection& projection) {
  return {index, pipeline::frame_pose(f, e, projection), true};
}

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

}  // namespace

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

}  // namespace seqloc::python
