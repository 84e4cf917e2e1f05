#include "seqloc/pipeline/backbone_calibration.hpp"

#include <cmath>

#include "seqloc/core/angles.hpp"
#include "seqloc/io/calibration_file.hpp"

namespace seqloc::pipeline {

std::optional<std::array<int, 3>> true_volume_cell(const io::RouteFrame& frame, const GridCrop& crop,
                                                   const osm::RegionProjection& projection, int height, int width,
                                                   int bins, double cell_m) {
  if (!frame.truth || !frame.truth->heading_deg) return std::nullopt;
  double gamma = 0;
  const auto truth = projection.forward(frame.truth->where, gamma);
  // The offset in grid metres, turned into the crop's axes (the inverse of filter::volume_cell_pose).
  const double dx = truth.x_m - crop.x, dy = truth.y_m - crop.y;
  const double a = crop.rotation_deg * core::kDegToRad;
  const double east = dx * std::cos(a) - dy * std::sin(a);
  const double north = dx * std::sin(a) + dy * std::cos(a);
  const auto u = static_cast<int>(std::lround(east / cell_m + (width - 1) / 2.0));
  const auto v = static_cast<int>(std::lround(-north / cell_m + (height - 1) / 2.0));
  // The crop's heading of grid heading h is h - rotation.
  const double heading = *frame.truth->heading_deg - gamma - crop.rotation_deg;
  const auto bin = static_cast<int>(((std::lround(heading * bins / 360.0) % bins) + bins) % bins);
  return std::array<int, 3>{v, u, bin};
}

matcher::CalibrationFit::Grid backbone_calibration_grid() {
  matcher::CalibrationFit::Grid grid;
  grid.temperatures.clear();
  for (int half_octave = -6; half_octave <= 6; ++half_octave) grid.temperatures.push_back(std::exp2(half_octave / 2.0));
  grid.blur_cells = {0, 1, 2, 3, 4};
  grid.blur_bins = {0, 1, 2, 3};
  return grid;
}

BackboneFit fit_backbone_calibration(const std::vector<io::Route>& routes, raster::CacheReader& cache,
                                     const LocalizeOptions& options, const std::function<void()>& on_frame) {
  LocalizeOptions as_given = options;
  as_given.volume_temperature = 1;
  as_given.volume_calibration = {};
  matcher::CalibrationFit fit(backbone_calibration_grid());
  const auto& projection = cache.metadata().projection();
  for (const auto& route : routes) {
    const FrameSource source = route_frames(route, cache, as_given);
    for (std::size_t i = 0; i < route.frames.size(); ++i) {
      const io::RouteFrame& f = route.frames[i];
      if (f.truth && f.truth->heading_deg) {
        const auto frame = source(i);
        const int H = frame->height, W = frame->width, N = frame->bins;
        const GridCrop crop = frame_crop(f, cache.grid(), projection);
        const auto cell = true_volume_cell(f, crop, projection, H, W, N, frame->cell_m);
        fit.add(hwn_values(*frame), H, W, N, (*cell)[0], (*cell)[1], (*cell)[2]);
      }
      if (on_frame) on_frame();
    }
  }
  BackboneFit result{fit.best(), 0};
  if (result.best.frames == 0) {
    throw DataError("no frame has a true pose (gt_lat, gt_lon, gt_heading_deg) inside its volume: nothing to fit");
  }
  result.as_given_nll = fit.mean_nll(1.0, matcher::VolumeCalibration{});  // 1 and 0s are on the grid
  return result;
}

std::string calibration_json(const BackboneFit& fit) {
  const auto& b = fit.best;
  return io::calibration_file_json({b.temperature, b.calibration.blur_cells, b.calibration.blur_bins,
                                    b.calibration.floor, b.nll, b.uniform_nll, fit.as_given_nll, b.frames, b.skipped});
}

void apply_calibration_file(const std::filesystem::path& path, LocalizeOptions& options) {
  const io::CalibrationFile file = io::read_calibration_file(path);
  LocalizeOptions applied = options;
  applied.volume_temperature = file.temperature;
  applied.volume_calibration = {file.blur_cells, file.blur_bins, file.floor};
  try {
    applied.validate();
  } catch (const std::exception& e) {
    throw DataError(path.string() + ": " + e.what());
  }
  options = applied;
}

}  // namespace seqloc::pipeline
