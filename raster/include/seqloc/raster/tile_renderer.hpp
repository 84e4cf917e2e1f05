#pragma once
// Renders the two raster layers of a region tile by tile (conventions.md section 2):
// - classes: three uint8 channels [areas, ways, nodes]; where several groups of a channel cover a
//   cell, the first in list order wins (OrienterNet's mask_to_idx); building areas are also drawn
//   as building_outline ways;
// - road distance: UInt16 centimetres to the nearest road cell, clamped, computed over the tile
//   plus a halo of at least the clamp so that tiles are seamless.

#include <cstdint>
#include <string>
#include <vector>

#include "seqloc/osm/features.hpp"
#include "seqloc/osm/projection.hpp"
#include "seqloc/raster/distance_transform.hpp"
#include "seqloc/raster/grid.hpp"
#include "seqloc/raster/rasterize.hpp"

namespace seqloc::raster {

/// Inclusive bounding box in global pixels.
struct PixelBox {
  std::int64_t u0 = 0, v0 = 0, u1 = -1, v1 = -1;
  void extend(Pixel p) {
    if (u1 < u0) {
      *this = {p.u, p.v, p.u, p.v};
      return;
    }
    u0 = std::min(u0, p.u);
    v0 = std::min(v0, p.v);
    u1 = std::max(u1, p.u);
    v1 = std::max(v1, p.v);
  }
};

/// The tiles of a grid, columns [c0, c1] and rows [r0, r1] (empty when c0 > c1 or r0 > r1).
struct TileSpan {
  std::int64_t c0 = 0, c1 = -1, r0 = 0, r1 = -1;
};
/// The tiles of `grid` whose pixels meet `box` grown by `margin` pixels: the tiles whose bins
/// name a feature of that box (the renderer's and preprocessing's blocks alike).
[[nodiscard]] TileSpan tiles_meeting(const RegionGrid& grid, const PixelBox& box, std::int64_t margin);

struct PixelNode {
  osm::Group group{};
  Pixel at;
};
struct PixelLine {
  osm::Group group{};
  std::vector<Pixel> points;
  PixelBox box;
};
struct PixelArea {
  osm::Group group{};
  std::vector<std::vector<Pixel>> rings;
  PixelBox box;
};
/// A road-group way in grid metres, unsnapped, for the cache's vector table.
struct RoadLine {
  std::int64_t osm_id;
  std::string highway;
  std::vector<osm::GridPoint> points;
};

/// Features projected to the region CRS and snapped to the lattice.
struct RegionFeatures {
  std::vector<PixelNode> nodes;
  std::vector<PixelLine> lines;
  std::vector<PixelArea> areas;
  std::vector<RoadLine> roads;
};

[[nodiscard]] RegionFeatures project_features(const osm::FeatureSet& features, const osm::RegionProjection& projection);

/// Per-thread scratch space of the renderer.
struct RenderScratch {
  PolygonScratch polygon;
  DistanceScratch distance;
  std::vector<std::uint8_t> road_mask;
  std::vector<std::uint32_t> squared;
};

class TileRenderer {
 public:
  /// `max_distance_m` is the clamp of the road distance (conventions.md: default 100 m).
  TileRenderer(const RegionFeatures& features, RegionGrid grid, double max_distance_m);

  /// The halo (pixels) around a tile within which roads set its distances: ceil(2 * clamp) + 1.
  [[nodiscard]] static int halo_for(double max_distance_m);

  [[nodiscard]] const RegionGrid& grid() const { return grid_; }
  [[nodiscard]] int halo_px() const { return halo_px_; }
  [[nodiscard]] std::uint16_t max_distance_cm() const { return max_cm_; }

  /// Interleaved RGB (R = areas, G = ways, B = nodes), 512 x 512 x 3. Returns false (and leaves
  /// `rgb` all zero) when no feature touches the tile.
  bool render_classes(std::int64_t col, std::int64_t row, RenderScratch& scratch, std::vector<std::uint8_t>& rgb) const;
  /// Road distance in cm, 512 x 512. Returns false (and fills the clamp) when no road is within
  /// the clamp of the tile.
  bool render_road_distance(std::int64_t col, std::int64_t row, RenderScratch& scratch,
                            std::vector<std::uint16_t>& cm) const;

  /// The road mask (1 = road cell) of any window, for tests and independent checks.
  void render_road_mask(const Window& window, std::vector<std::uint8_t>& mask) const;
  /// The classes of any window from all features (no tile bins): the reference that tiles must
  /// reproduce. Interleaved RGB, window.width x window.height x 3.
  void render_classes_window(const Window& window, RenderScratch& scratch, std::vector<std::uint8_t>& rgb) const;

 private:
  [[nodiscard]] std::size_t tile_index(std::int64_t col, std::int64_t row) const {
    return static_cast<std::size_t>(row * grid_.tiles_wide() + col);
  }
  void draw_roads(const Window& window, const std::vector<std::uint32_t>& lines, std::vector<std::uint8_t>& mask) const;
  void draw_classes(const Window& window, const std::vector<std::uint32_t>& areas, const std::vector<std::uint32_t>& lines,
                    const std::vector<std::uint32_t>& nodes, RenderScratch& scratch, std::vector<std::uint8_t>& rgb) const;

  const RegionFeatures& features_;
  RegionGrid grid_;
  int halo_px_;
  std::uint16_t max_cm_;
  DistanceQuantizer quantize_;
  std::vector<std::vector<std::uint32_t>> node_bins_, line_bins_, area_bins_, road_bins_;
  std::vector<std::uint32_t> road_lines_;  ///< indices of road-group lines
  std::vector<std::uint32_t> all_nodes_, all_lines_, all_areas_;
};

}  // namespace seqloc::raster
