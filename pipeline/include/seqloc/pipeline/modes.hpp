#pragma once
// The localization modes (docs/localize.md): each a small class behind one interface that takes
// a route's frames in order and gives one pose per frame. localize_route drives them; a new mode
// or estimator is one class here and one line in make_mode.
//   single   each frame's own argmax                       (modes/single.cpp)
//   offline  each frame with its neighbours aligned to it  (modes/offline.cpp)
//   online   the sequential filter without ETU, MGR, PAS   (modes/sequential.cpp)
//   seqloc   the sequential filter as configured           (modes/sequential.cpp)
//   smooth   the filter forward, then backward: every frame  (modes/smooth.cpp)
// online and seqloc take LocalizeOptions::lag (fixed-lag smoothing).

#include <cstddef>
#include <memory>
#include <optional>
#include <vector>

#include "seqloc/pipeline/frame_prefetcher.hpp"
#include "seqloc/pipeline/localize.hpp"
#include "seqloc/pipeline/region_catalog.hpp"
#include "seqloc/pipeline/region_window.hpp"

namespace seqloc::pipeline {

/// One mode's pose for one frame: region grid metres, grid heading, and what the frame weighed.
struct FrameEstimate {
  double x_m = 0, y_m = 0;
  double grid_heading_deg = 0;
  double entropy = 0;  ///< the frame volume's normalized entropy
  double etu_weight = 1;
  double volume_power = 1;  ///< self-calibration's power for the frame (1 where it does not apply)
  bool relocalized = false;
  /// From the belief the estimate came from (modes that have one; uncertainty/pose_uncertainty.hpp).
  std::optional<io::FramePose::Uncertainty> uncertainty;
};

/// The uncertainty of `estimate` (window cells, grid heading) under `belief`, as the outputs hold
/// it (the window's east and north are the region grid's x and y).
[[nodiscard]] io::FramePose::Uncertainty uncertainty_of(const filter::BeliefVolume& belief,
                                                        const filter::Pose& estimate, int threads);

/// The pose a mode estimated for frame `f`, in every form the outputs take (region metres,
/// lat/lon, compass and grid heading), with its errors against the frame's ground truth.
[[nodiscard]] io::FramePose frame_pose(const io::RouteFrame& f, const FrameEstimate& e,
                                       const osm::RegionProjection& projection);

/// What a mode works on: one route against one region cache, or against the regions of a catalog
/// for a route that crosses from one into the next. The references outlive the mode.
struct RouteContext {
  const io::Route& route;
  raster::CacheReader& cache;  ///< the first frame's region
  const LocalizeOptions& options;
  const FrameInspector& inspect;  ///< may be empty
  /// For a route over a catalog's regions: the catalog and each frame's region in it (every mode
  /// follows a route from one region into the next). Null when every frame is in `cache`.
  const RegionCatalog* catalog = nullptr;
  const std::vector<std::size_t>* regions = nullptr;
};

class LocalizationMode {
 public:
  virtual ~LocalizationMode() = default;
  LocalizationMode(const LocalizationMode&) = delete;
  LocalizationMode& operator=(const LocalizationMode&) = delete;

  /// Whether the frame after the one being estimated should be prepared meanwhile (a mode that
  /// reads a range of frames itself says no).
  [[nodiscard]] virtual bool lookahead() const { return true; }
  /// Frame i's pose; frames come in order, `crop` is frame_crop of frame i. The mode releases the
  /// frames it no longer needs.
  [[nodiscard]] virtual FrameEstimate estimate(std::size_t i, const GridCrop& crop, FramePrefetcher& frames) = 0;
  /// Adds what the mode gathered along the route (re-centring, filter time, kept beliefs).
  virtual void finish(io::RouteResult& result);

 protected:
  explicit LocalizationMode(const RouteContext& context)
      : context_(context), projection_(context.cache.metadata().projection()) {}
  /// What etu_weight a frame of this entropy gets under the options (reported for every mode).
  [[nodiscard]] double reported_etu_weight(double entropy) const;
  /// Frame i's region: its index in the catalog (0 for one region), its cache and its CRS.
  [[nodiscard]] std::size_t region_of(std::size_t i) const;
  [[nodiscard]] raster::CacheReader& cache_of(std::size_t i) const;
  [[nodiscard]] const osm::RegionProjection& projection_of(std::size_t i) const;
  /// Frame s's crop in the grid of frame t's region (frame_crop in its own, carried across).
  [[nodiscard]] GridCrop crop_in_region_of(std::size_t s, std::size_t t) const;

  RouteContext context_;
  osm::RegionProjection projection_;  ///< context_.cache's
  double filter_seconds_ = 0;
};

/// The mode's class for `mode`.
[[nodiscard]] std::unique_ptr<LocalizationMode> make_mode(io::Mode mode, const RouteContext& context);

}  // namespace seqloc::pipeline
