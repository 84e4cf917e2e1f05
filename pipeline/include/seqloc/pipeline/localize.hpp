#pragma once
// Localizing a route against a region cache with the SeqLoc filter (or a baseline): the belief
// window follows the vehicle, the road-distance window is stitched from the cache's tiles, and
// every pose crosses the interface in the conventions' terms (conventions.md sections 1 and 7).

#include <algorithm>
#include <array>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "seqloc/filter/config.hpp"
#include "seqloc/filter/seqloc_filter.hpp"
#include "seqloc/io/results.hpp"
#include "seqloc/io/route.hpp"
#include "seqloc/matcher/calibration.hpp"
#include "seqloc/matcher/matcher.hpp"
#include "seqloc/pipeline/forward_filter.hpp"
#include "seqloc/pipeline/frame_prefetcher.hpp"
#include "seqloc/pipeline/region_window.hpp"
#include "seqloc/raster/cache.hpp"

namespace seqloc::pipeline {

class RegionCatalog;

struct LocalizeOptions {
  filter::FilterConfig filter;  ///< window size, components, threads (online mode turns ETU/MGR/PAS off)
  /// Re-centre the window when the estimate comes closer than this fraction of the window's
  /// size to an edge.
  double recentre_margin = 0.25;
  /// Offline mode: frames within this many of t are aligned to t and summed (< 0: all of them).
  int offline_half_window = 10;
  /// Online and seqloc modes: each frame's pose given the frames up to `lag` after it (fixed-lag
  /// smoothing, for real time with a delay of `lag` frames); 0: the filter's own pose.
  int lag = 0;
  /// The built-in matcher, for frames with an observation instead of a volume.
  matcher::MatcherConfig matcher;
  /// Every frame's volume (a backbone's or the matcher's) is tempered before filtering: its
  /// log-probabilities divided by T and renormalized (filter::temper_frame with power 1 / T).
  /// T > 1 flattens an overconfident backbone; T < 1 sharpens. 1: as given.
  double volume_temperature = 1.0;
  /// Then blurred and floored (calibration.hpp; identity by default), as `seqloc calibrate` fits a
  /// backbone (`--calibration calibration.json` sets both).
  matcher::VolumeCalibration volume_calibration;
  /// Largest distance between consecutive crop centres (m) before the route is refused as
  /// implausible; 0: the belief window's size (a larger jump leaves the window anyway).
  double max_crop_jump_m = 0;
  /// How far beyond the region's edge a crop centre may lie (m). 0: crops must be in the region
  /// (a route that drives off the map has nothing to be localized against there).
  double max_crop_outside_m = 0;
  /// localize_routes: memory for the frames the modes of a route share (float16, MB, all routes in
  /// flight together); frames beyond it go to an unlinked temporary file in `spill_dir`.
  std::size_t frame_memory_mb = 1024;
  /// Online and seqloc modes: keep each frame's belief summed over headings in RouteResult::beliefs
  /// (frames x window cells x 4 bytes per route and mode), for pictures drawn later.
  bool keep_beliefs = false;
  std::filesystem::path spill_dir;  ///< empty: the system's temporary directory
  /// Where the forward filter of the online, seqloc and smooth modes runs (docs/gpu.md); single
  /// and offline, and the backward passes of smooth and of a lag, run on the CPU.
  Device device = Device::cpu;

  [[nodiscard]] double crop_jump_limit_m() const {
    return max_crop_jump_m > 0 ? max_crop_jump_m : std::max(filter.width, filter.height) * raster::kCellM;
  }
  void validate() const;
};

/// A frame's volume made ready for the filter as localize makes every frame: prepared for
/// options.filter.headings, tempered by options.volume_temperature, blurred and floored by
/// options.volume_calibration. Throws filter::FilterError
/// for bad values (NaN, infinities, negative probabilities) or shapes.
[[nodiscard]] filter::PreparedFrame prepare_volume(const filter::FrameVolume& volume, const LocalizeOptions& options);

/// A prepared frame's log-probabilities ([bin][v][u]) in a volume's (H, W, N) order.
[[nodiscard]] std::vector<float> hwn_values(const filter::PreparedFrame& frame);

/// The route's own frames: its .npy volumes, or the built-in matcher run on its observations
/// against the cache's class raster. Throws DataError naming the file.
[[nodiscard]] FrameSource route_frames(const io::Route& route, raster::CacheReader& cache,
                                       const LocalizeOptions& options);

/// route_frames through a FrameStore with `readers` readers: each frame with the float16 values
/// that localize_routes gives every mode, held only until it has been taken that often.
/// localize_route's default, and what render and the benchmark use to see the frames as localize
/// saw them.
[[nodiscard]] FrameSource stored_route_frames(const io::Route& route, raster::CacheReader& cache,
                                              const LocalizeOptions& options, int readers = 1);

/// How often a mode takes each frame of `route` from the route's FrameStore (which holds a frame
/// until its last reader took it): 1, but 2 for smooth on a route the matcher scores (smooth reads
/// every frame in its forward and again in its backward pass; a .npy volume is read again rather
/// than held, a volume the matcher scored is held rather than scored again).
[[nodiscard]] int frame_reads(io::Mode mode, const io::Route& route);

/// The built-in matcher's raw volume for an observation frame: (size, size, headings) float32
/// log-likelihood scores over the frame's crop (before any calibration). Throws DataError for an
/// unreadable observation.
[[nodiscard]] std::vector<float> match_frame(const io::RouteFrame& frame, raster::CacheReader& cache,
                                             const matcher::BevMatcher& matcher);

/// Where a frame's crop lies in the region grid (GridCrop, region_window.hpp).
[[nodiscard]] GridCrop frame_crop(const io::RouteFrame& frame, const raster::RegionGrid& grid,
                                  const osm::RegionProjection& projection);

/// Checks a route's crops against the region before any work: every crop centre must lie in the
/// region grid (or within options.max_crop_outside_m of it), and consecutive centres at most
/// options.crop_jump_limit_m() apart. Throws DataError "DIR/frames.csv:LINE: ..." (a lat/lon crop
/// that would fall in the region with its two coordinates exchanged is called swapped).
void check_crops(const io::Route& route, const raster::RegionGrid& grid, const osm::RegionProjection& projection,
                 const LocalizeOptions& options);

/// What a frame left behind, for pictures: its prepared volume and crop, and for the online modes
/// the belief after the step (window cell (0, 0) is region pixel (origin_u, origin_v)).
struct FrameInspection {
  std::size_t index = 0;
  const filter::PreparedFrame* frame = nullptr;
  GridCrop crop;
  const filter::BeliefVolume* belief = nullptr;  ///< null for single and offline
  std::int64_t origin_u = 0, origin_v = 0;        ///< region pixel of the belief's cell (0, 0)
};
using FrameInspector = std::function<void(const FrameInspection&)>;

/// Runs one route; `on_frame` (optional) is called after each frame, from the calling thread.
/// `source` defaults to stored_route_frames(route, cache, options); a caller running several
/// modes on one route may share one that keeps the frames. Throws DataError (volumes), filter::FilterError
/// or raster::CacheError. Routes may run in parallel threads on one CacheReader.
[[nodiscard]] io::RouteResult localize_route(const io::Route& route, raster::CacheReader& cache,
                                             const LocalizeOptions& options, io::Mode mode,
                                             const std::function<void()>& on_frame = {}, FrameSource source = {},
                                             const FrameInspector& inspect = {});

/// What localize_routes did: one result per (route, mode), route-major and the modes in the
/// order given; and how the routes' shared frames were held.
struct BatchResult {
  std::vector<io::RouteResult> results;
  std::size_t frames_made = 0;     ///< volumes scored or read and prepared (once per frame and route)
  std::size_t frames_spilled = 0;  ///< of those, frames held in the temporary file
  std::size_t peak_frame_memory_bytes = 0;  ///< the largest float16 memory one route's frames took
};

/// Runs every mode on every route: every route's crops are checked (check_crops) before any job
/// starts, then (route, mode) jobs run side by side on options.filter.threads
/// threads (one filter thread each when there are several jobs, all of them for a single job).
/// The modes of a route share its frames through a FrameStore, so each volume is scored or read
/// once. `on_frame` (optional) is called after each frame of each job, from the worker threads.
/// The first error of any job stops the others from starting and is rethrown.
[[nodiscard]] BatchResult localize_routes(const std::vector<io::Route>& routes, raster::CacheReader& cache,
                                          const LocalizeOptions& options, const std::vector<io::Mode>& modes,
                                          const std::function<void()>& on_frame = {});

/// The same over several regions (region_catalog.hpp): each frame is placed in a region, staying
/// in one while its crop is half a belief window inside it. A route inside one region runs as
/// above against that region. A route that crosses regions runs in every mode, each pose in its
/// own frame's region's CRS (FramePose::region): the sequential filter's belief is handed over at
/// each crossing (SequentialLocalizer::hand_over), smooth's beta carried back the same way, and
/// offline's window is in frame t's region with its neighbours' crops carried into it.
/// What localize_routes checks of a route before any work over a catalog: each frame in a
/// region and each leg's crops (check_crops). Throws DataError "DIR/frames.csv:LINE: ...".
void check_route(const io::Route& route, const RegionCatalog& catalog, const LocalizeOptions& options);

[[nodiscard]] BatchResult localize_routes(const std::vector<io::Route>& routes, const RegionCatalog& catalog,
                                          const LocalizeOptions& options, const std::vector<io::Mode>& modes,
                                          const std::function<void()>& on_frame = {});

/// Zero-mean Gaussian noise on each odometry increment in the KITTI convention: translation sigma
/// `translation_pct` % of the step length (on forward and left), heading sigma
/// `rotation_deg_per_m` times the step length; integrated by the filter, so the trajectory drifts.
/// Deterministic for a seed; ground truth is never touched.
void perturb_odometry(io::Route& route, double translation_pct, double rotation_deg_per_m, std::uint64_t seed);

}  // namespace seqloc::pipeline
