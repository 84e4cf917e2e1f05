#pragma once
// A backbone's calibration from routes with ground truth (`seqloc calibrate`): the temperature,
// blur and floor of calibration.hpp fitted to any backbone's volumes by the mean NLL of the true
// cell, as the built-in matcher's were, written as calibration.json and applied by `seqloc
// localize --calibration` and the Python module. For a user without ground truth the filter's
// self-calibration estimates the temperature alone (docs/filter.md, "Self-calibration").

#include <array>
#include <cstddef>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "seqloc/matcher/calibration.hpp"
#include "seqloc/pipeline/localize.hpp"

namespace seqloc::pipeline {

/// The volume cell (v, u, bin) of a frame's ground truth, nearest, for a volume of the given shape
/// lying on `crop` (its axes turned clockwise by crop.rotation_deg from grid north); nullopt
/// without a true heading.
[[nodiscard]] std::optional<std::array<int, 3>> true_volume_cell(const io::RouteFrame& frame, const GridCrop& crop,
                                                                 const osm::RegionProjection& projection, int height,
                                                                 int width, int bins, double cell_m);

/// The grid a backbone's calibration is fitted on: temperatures of log-probabilities from 1/8 to
/// 8 in half octaves, blurs up to 4 cells and 3 bins, the floors of CalibrationFit's grid.
[[nodiscard]] matcher::CalibrationFit::Grid backbone_calibration_grid();

struct BackboneFit {
  matcher::CalibrationFit::Result best;  ///< the fit (its NLL, a uniform volume's, the frames)
  double as_given_nll = 0;      ///< the mean NLL of the volumes as given (temperature 1, no blur, no floor)
};

/// Fits the calibration on every frame with a true pose: each frame as localize reads it (the
/// route's .npy volumes, or the built-in matcher's), before any temperature or calibration of
/// `options`. `on_frame` (optional) is called after each frame. Throws DataError when no frame's
/// true pose lies in its volume.
[[nodiscard]] BackboneFit fit_backbone_calibration(const std::vector<io::Route>& routes, raster::CacheReader& cache,
                                                   const LocalizeOptions& options,
                                                   const std::function<void()>& on_frame = {});

/// The fit as calibration.json (io::calibration_file_json, the file's one writer).
[[nodiscard]] std::string calibration_json(const BackboneFit& fit);

/// Reads calibration.json (io::read_calibration_file, its one reader) into the options localize
/// applies (volume_temperature and volume_calibration), checked as localize checks them. Throws
/// DataError naming the file and what is wrong.
void apply_calibration_file(const std::filesystem::path& path, LocalizeOptions& options);

}  // namespace seqloc::pipeline
