#pragma once
// The belief window over a region: W x H cells of the region grid (0.5 m) whose cell (0, 0) is
// region pixel origin(). It owns that one origin, converts between region metres, region pixels
// and window cells, re-centres on the vehicle by whole cells, and holds the road distance over
// the window (metres), stitched from the cache's tiles when first needed after a move.

#include <array>
#include <cstdint>
#include <span>
#include <optional>
#include <vector>

#include "seqloc/filter/belief.hpp"
#include "seqloc/filter/types.hpp"
#include "seqloc/osm/projection.hpp"
#include "seqloc/raster/cache.hpp"

namespace seqloc::pipeline {

/// The region-grid centre of a frame's crop (x, y in metres) and the rotation of its north from
/// grid north (degrees clockwise). Observation frames are matched on a crop in grid coordinates
/// whose centre is snapped to the nearest cell corner, so that volume and map cells coincide.
struct GridCrop {
  double x = 0, y = 0, rotation_deg = 0;
};

class RegionWindow {
 public:
  /// A window of width x height cells at origin (0, 0); centre_on() places it.
  RegionWindow(raster::CacheReader& cache, int width, int height);

  [[nodiscard]] int width() const { return width_; }
  [[nodiscard]] int height() const { return height_; }
  /// The region cache the window lies in.
  [[nodiscard]] raster::CacheReader& cache() const { return *cache_; }
  /// Region pixel (u east, v south) of window cell (0, 0).
  [[nodiscard]] std::int64_t origin_u() const { return origin_u_; }
  [[nodiscard]] std::int64_t origin_v() const { return origin_v_; }

  /// Window position (cells, continuous; integral at cell centres) of region grid metres.
  [[nodiscard]] double u_of(double x_m) const { return grid_.region_u(x_m) - static_cast<double>(origin_u_); }
  [[nodiscard]] double v_of(double y_m) const { return grid_.region_v(y_m) - static_cast<double>(origin_v_); }
  /// Region grid metres of window position (u, v).
  [[nodiscard]] double x_of(double u) const {
    return grid_.min_x() + (u + static_cast<double>(origin_u_) + 0.5) * raster::kCellM;
  }
  [[nodiscard]] double y_of(double v) const {
    return grid_.max_y() - (v + static_cast<double>(origin_v_) + 0.5) * raster::kCellM;
  }
  /// Where a frame's crop lies in the window, as the filter takes it.
  [[nodiscard]] filter::CropPose crop_pose(const GridCrop& crop) const {
    return {u_of(crop.x), v_of(crop.y), crop.rotation_deg};
  }

  /// Moves the window so that the region pixel nearest to (x_m, y_m) is its centre cell
  /// (width / 2, height / 2).
  void centre_on(double x_m, double y_m);
  /// The whole-cell move (du, dv) that brings window position (u, v) to the centre when it lies
  /// closer than `margin` (a fraction of the window's size) to an edge, or outside; none otherwise.
  [[nodiscard]] std::optional<std::array<int, 2>> recentre_shift(double u, double v, double margin) const;
  /// Moves the window by (du, dv) cells: the new cell (u, v) is the old (u + du, v + dv).
  void shift(int du, int dv);
  /// Places the window's cell (0, 0) at region pixel (origin_u, origin_v) (where another window was).
  void move_to(std::int64_t origin_u, std::int64_t origin_v);

  /// The road distance over the window in metres, width x height row-major (v, u); cells outside
  /// the region read as the cache's fill. Read from the cache on the first call after a move.
  [[nodiscard]] std::span<const float> road_distance_m();

 private:
  raster::CacheReader* cache_;
  raster::RegionGrid grid_;
  int width_, height_;
  std::int64_t origin_u_ = 0, origin_v_ = 0;
  std::vector<float> road_m_;
  bool road_stale_ = true;
};

/// Across regions (a route crossing from one region's grid into the next). The same place and the
/// same compass direction in `to` as in `from`: positions through the ellipsoid, grid headings
/// turned by the difference of the two CRSs' meridian convergence there.
///
/// `belief` over window `from` resampled onto window `to`: each cell of `to` takes the cell of
/// `from` nearest the same place, its headings interpolated between bins; a cell whose place lies
/// outside `from` takes the belief's least value. The result sums to 1 (a backward filter's beta,
/// which has no scale of its own, is carried the same way).
[[nodiscard]] filter::BeliefVolume carry_belief(const filter::BeliefVolume& belief, const RegionWindow& from,
                                                const RegionWindow& to);
/// A pose in `from`'s cells as one in `to`'s.
[[nodiscard]] filter::Pose carry_pose(const filter::Pose& pose, const RegionWindow& from, const RegionWindow& to);
/// A crop in one region's grid as one in another's (its centre and the direction of its north).
[[nodiscard]] GridCrop carry_crop(const GridCrop& crop, const osm::RegionProjection& from,
                                  const osm::RegionProjection& to);

}  // namespace seqloc::pipeline
