#include "seqloc/raster/tile_renderer.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <span>

namespace seqloc::raster {
namespace {

Pixel to_pixel(const osm::RegionProjection& projection, osm::GeoPoint p) {
  const auto g = projection.forward(p);
  return snap(pixel_u(g.x_m), pixel_v(g.y_m));
}

// Calls f(index) for every tile whose pixels intersect the box grown by `margin` pixels.
template <class F>
void for_each_tile(const RegionGrid& grid, const PixelBox& box, std::int64_t margin, F&& f) {
  const TileSpan t = tiles_meeting(grid, box, margin);
  for (std::int64_t r = t.r0; r <= t.r1; ++r) {
    for (std::int64_t c = t.c0; c <= t.c1; ++c) f(static_cast<std::size_t>(r * grid.tiles_wide() + c));
  }
}

// OrienterNet's mask_to_idx: the first group in list order wins a cell.
inline void paint(std::uint8_t& cell, std::uint8_t code) {
  if (cell == 0 || code < cell) cell = code;
}

}  // namespace

TileSpan tiles_meeting(const RegionGrid& grid, const PixelBox& box, std::int64_t margin) {
  const Pixel o = grid.origin();
  auto floor_div = [](std::int64_t a, std::int64_t b) { return a >= 0 ? a / b : -((-a + b - 1) / b); };
  return {std::max<std::int64_t>(0, floor_div(box.u0 - margin - o.u, kTilePx)),
          std::min<std::int64_t>(grid.tiles_wide() - 1, floor_div(box.u1 + margin - o.u, kTilePx)),
          std::max<std::int64_t>(0, floor_div(box.v0 - margin - o.v, kTilePx)),
          std::min<std::int64_t>(grid.tiles_high() - 1, floor_div(box.v1 + margin - o.v, kTilePx))};
}

RegionFeatures project_features(const osm::FeatureSet& features, const osm::RegionProjection& projection) {
  RegionFeatures out;
  out.nodes.reserve(features.points.size());
  for (const auto& p : features.points) out.nodes.push_back({p.group, to_pixel(projection, p.where)});
  out.lines.reserve(features.lines.size());
  for (const auto& l : features.lines) {
    PixelLine line{l.group, {}, {}};
    line.points.reserve(l.points.size());
    for (const auto& p : l.points) {
      line.points.push_back(to_pixel(projection, p));
      line.box.extend(line.points.back());
    }
    if (l.group == osm::kRoad) {
      RoadLine road{l.osm_id, l.highway, {}};
      road.points.reserve(l.points.size());
      for (const auto& p : l.points) road.points.push_back(projection.forward(p));
      out.roads.push_back(std::move(road));
    }
    out.lines.push_back(std::move(line));
  }
  out.areas.reserve(features.areas.size());
  for (const auto& a : features.areas) {
    PixelArea area{a.group, {}, {}};
    for (const auto& ring : a.rings) {
      std::vector<Pixel> pixels;
      pixels.reserve(ring.size());
      for (const auto& p : ring) {
        pixels.push_back(to_pixel(projection, p));
        area.box.extend(pixels.back());
      }
      area.rings.push_back(std::move(pixels));
    }
    out.areas.push_back(std::move(area));
  }
  return out;
}

int TileRenderer::halo_for(double max_distance_m) {
  return static_cast<int>(std::ceil(max_distance_m * kPixelsPerMetre)) + 1;
}

TileRenderer::TileRenderer(const RegionFeatures& features, RegionGrid grid, double max_distance_m)
    : features_(features),
      grid_(grid),
      halo_px_(halo_for(max_distance_m)),
      max_cm_(static_cast<std::uint16_t>(std::lround(max_distance_m * 100.0))),
      quantize_(kCellM, max_cm_) {
  assert(max_distance_m > 0 && max_distance_m * 100.0 < 65535.0);
  const auto n = static_cast<std::size_t>(grid_.tile_count());
  node_bins_.resize(n);
  line_bins_.resize(n);
  area_bins_.resize(n);
  road_bins_.resize(n);
  for (std::uint32_t i = 0; i < features_.nodes.size(); ++i) all_nodes_.push_back(i);
  for (std::uint32_t i = 0; i < features_.lines.size(); ++i) all_lines_.push_back(i);
  for (std::uint32_t i = 0; i < features_.areas.size(); ++i) all_areas_.push_back(i);
  for (std::uint32_t i = 0; i < features_.nodes.size(); ++i) {
    PixelBox box;
    box.extend(features_.nodes[i].at);
    for_each_tile(grid_, box, 0, [&](std::size_t t) { node_bins_[t].push_back(i); });
  }
  for (std::uint32_t i = 0; i < features_.lines.size(); ++i) {
    const auto& line = features_.lines[i];
    for_each_tile(grid_, line.box, 0, [&](std::size_t t) { line_bins_[t].push_back(i); });
    if (line.group == osm::kRoad) {
      road_lines_.push_back(i);
      for_each_tile(grid_, line.box, halo_px_, [&](std::size_t t) { road_bins_[t].push_back(i); });
    }
  }
  for (std::uint32_t i = 0; i < features_.areas.size(); ++i) {
    for_each_tile(grid_, features_.areas[i].box, 0, [&](std::size_t t) { area_bins_[t].push_back(i); });
  }
}

bool TileRenderer::render_classes(std::int64_t col, std::int64_t row, RenderScratch& scratch,
                                  std::vector<std::uint8_t>& rgb) const {
  assert(grid_.contains_tile(col, row));
  const std::size_t t = tile_index(col, row);
  const Pixel o = grid_.tile_origin(col, row);
  draw_classes(Window{o.u, o.v, kTilePx, kTilePx}, area_bins_[t], line_bins_[t], node_bins_[t], scratch, rgb);
  return !(node_bins_[t].empty() && line_bins_[t].empty() && area_bins_[t].empty());
}

void TileRenderer::render_classes_window(const Window& window, RenderScratch& scratch,
                                         std::vector<std::uint8_t>& rgb) const {
  draw_classes(window, all_areas_, all_lines_, all_nodes_, scratch, rgb);
}

void TileRenderer::draw_classes(const Window& w, const std::vector<std::uint32_t>& areas,
                                const std::vector<std::uint32_t>& lines, const std::vector<std::uint32_t>& nodes,
                                RenderScratch& scratch, std::vector<std::uint8_t>& rgb) const {
  rgb.assign(static_cast<std::size_t>(w.width) * static_cast<std::size_t>(w.height) * 3, 0);
  auto plotter = [&](osm::Group group) {
    const auto channel = static_cast<std::size_t>(group.channel);
    const std::uint8_t code = group.code();
    return [&rgb, &w, channel, code](std::int64_t u, std::int64_t v) { paint(rgb[w.index(u, v) * 3 + channel], code); };
  };
  for (std::uint32_t i : areas) {
    const auto& area = features_.areas[i];
    for_each_polygon_cell(std::span<const std::vector<Pixel>>(area.rings), w, scratch.polygon, plotter(area.group));
    if (area.group == osm::kBuildingArea) {
      auto outline = plotter(osm::kBuildingOutline);
      for (const auto& ring : area.rings) for_each_ring_cell(std::span<const Pixel>(ring), w, outline);
    }
  }
  for (std::uint32_t i : lines) {
    const auto& line = features_.lines[i];
    for_each_polyline_cell(std::span<const Pixel>(line.points), w, plotter(line.group));
  }
  for (std::uint32_t i : nodes) {
    const auto& node = features_.nodes[i];
    if (w.contains(node.at.u, node.at.v)) plotter(node.group)(node.at.u, node.at.v);
  }
}

void TileRenderer::draw_roads(const Window& window, const std::vector<std::uint32_t>& lines,
                              std::vector<std::uint8_t>& mask) const {
  mask.assign(static_cast<std::size_t>(window.width * window.height), 0);
  auto mark = [&](std::int64_t u, std::int64_t v) { mask[window.index(u, v)] = 1; };
  for (std::uint32_t i : lines) for_each_polyline_cell(std::span<const Pixel>(features_.lines[i].points), window, mark);
}

void TileRenderer::render_road_mask(const Window& window, std::vector<std::uint8_t>& mask) const {
  draw_roads(window, road_lines_, mask);
}

bool TileRenderer::render_road_distance(std::int64_t col, std::int64_t row, RenderScratch& scratch,
                                        std::vector<std::uint16_t>& cm) const {
  assert(grid_.contains_tile(col, row));
  const std::size_t t = tile_index(col, row);
  cm.assign(static_cast<std::size_t>(kTilePx) * kTilePx, max_cm_);
  if (road_bins_[t].empty()) return false;
  const Pixel o = grid_.tile_origin(col, row);
  const int side = kTilePx + 2 * halo_px_;
  const Window w{o.u - halo_px_, o.v - halo_px_, side, side};
  draw_roads(w, road_bins_[t], scratch.road_mask);
  if (std::find(scratch.road_mask.begin(), scratch.road_mask.end(), 1) == scratch.road_mask.end()) return false;
  squared_distance(scratch.road_mask, side, side, halo_px_, halo_px_, kTilePx, kTilePx, scratch.distance,
                   scratch.squared, quantize_.reach_cells());
  for (std::size_t i = 0; i < cm.size(); ++i) cm[i] = quantize_(scratch.squared[i]);
  return true;
}

}  // namespace seqloc::raster
