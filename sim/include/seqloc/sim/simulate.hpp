#pragma once
// The route simulator (docs/simulate.md): routes driven along the cache's road network, each frame
// with a ground-truth pose, a BEV observation rendered from the map through a camera-like
// visibility footprint and corrupted as real perception is, a crop around a GPS-like fix, and
// odometry from the ground truth. Everything is drawn from one seeded generator.

#include <cstdint>
#include <filesystem>
#include <functional>

#include "seqloc/io/observation.hpp"
#include "seqloc/raster/cache.hpp"

namespace seqloc::sim {

/// What the camera sees and how perception fails. The defaults are the calibration recorded in
/// docs/simulate.md.
struct ObservationModel {
  double range_m = 15.0;        ///< visibility radius (the observation's side is 2 * range + 0.5 m)
  double fov_deg = 360.0;       ///< field of view, centred on forward (360 = panorama)
  bool occlusion = true;        ///< buildings hide what lies behind them
  double class_miss = 0.5;      ///< per frame and seen class: the whole class is missed
  double cell_dropout = 0.5;    ///< per seen non-background cell: missed
  double spurious_blobs = 8.0;  ///< mean number (Poisson) of blobs of a wrong class
  double jitter_m = 1.5;        ///< sigma of the observation's position error
  double jitter_deg = 4.0;      ///< sigma of its heading error
  double wrong_frame = 0.1;     ///< probability that a frame shows another place altogether

  void validate() const;  ///< throws UsageError naming the field
  [[nodiscard]] int side() const;
};

struct SimulateOptions {
  int routes = 20;
  int frames = 60;
  std::uint64_t seed = 1;
  double min_spacing_m = 3.0;  ///< distance driven between frames, uniform in [min, max]
  double max_spacing_m = 10.0;
  double speed_mps = 10.0;    ///< for timestamps
  double gps_error_m = 32.0;  ///< radius of the crop centre's error (uniform in the disc)
  double gps_drift_m = 1.0;   ///< per-frame random walk of that error (kept within the radius)
  int crop_size = 128;        ///< the matcher's volume side, written to route.json for reference
  ObservationModel camera;

  void validate() const;
};

/// A pose of the ground truth in the region grid.
struct GridPose {
  double x = 0, y = 0;
  double heading_deg = 0;  ///< grid heading, clockwise from grid north
};

/// Renders the observation at `pose` from the region's class raster (no corruption).
[[nodiscard]] io::Observation render_observation(raster::CacheReader& cache, const GridPose& pose,
                                                 const ObservationModel& camera);

/// Writes `options.routes` route directories route_000, route_001, ... under `out` (a new folder
/// written as out + ".partial" and renamed when complete). `progress(done, total)` after each
/// route. Throws DataError if the network has no path long enough, CacheError from the cache.
void simulate_routes(raster::CacheReader& cache, const SimulateOptions& options, const std::filesystem::path& out,
                     const std::function<void(int, int)>& progress = {});

}  // namespace seqloc::sim
