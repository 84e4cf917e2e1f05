#pragma once
// Rasterization primitives on the global pixel lattice (see grid.hpp). Every primitive is defined
// on whole-lattice vertices and visits only the cells of a window, so drawing a feature into any
// window gives exactly the cells of drawing it into one big raster: tiles are seamless by
// construction, whatever their halo.
//
// - snap(): a vertex goes to the nearest cell centre, ties to even, as OrienterNet rounds its
//   pixel coordinates (numpy round) before handing them to OpenCV.
// - Lines are 1 px, 8-connected, the cells OpenCV's 8-connected line (cv::polylines) draws:
//   along the major axis every cell, on the minor axis the cell nearest to the exact line, an
//   exact tie going toward the segment's start, where the start is the endpoint with the smaller
//   u (OpenCV's LineIterator walks left to right whichever way the segment is given). A segment
//   thus gives the same cells in both directions. Unlike OpenCV, a segment is never clipped to a
//   canvas: cells are computed on the global lattice, so any window sees the same cells.
// - Polygons: a cell is filled when its centre is inside the rings under the even-odd rule
//   (half-open: a centre on a left edge is in, on a right edge is out), plus every ring drawn as
//   a line, as OpenCV's fillPoly draws the outline too. Thin polygons thus never vanish.

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include "seqloc/raster/grid.hpp"

namespace seqloc::raster {

/// A rectangle of global pixels: u in [u0, u0 + width), v in [v0, v0 + height).
struct Window {
  std::int64_t u0 = 0, v0 = 0, width = 0, height = 0;

  [[nodiscard]] bool contains(std::int64_t u, std::int64_t v) const {
    return u >= u0 && v >= v0 && u < u0 + width && v < v0 + height;
  }
  [[nodiscard]] std::size_t index(std::int64_t u, std::int64_t v) const {
    return static_cast<std::size_t>((v - v0) * width + (u - u0));
  }
};

/// Nearest lattice point of continuous global pixel coordinates, ties to even.
inline Pixel snap(double u, double v) {
  return {static_cast<std::int64_t>(std::nearbyint(u)), static_cast<std::int64_t>(std::nearbyint(v))};
}

/// Calls plot(u, v) for each cell of the segment a-b inside the window.
template <class Plot>
void for_each_line_cell(Pixel a, Pixel b, const Window& w, Plot&& plot) {
  if (b.u < a.u || (b.u == a.u && b.v < a.v)) std::swap(a, b);
  const std::int64_t du = b.u - a.u;  // >= 0
  const std::int64_t dv = b.v - a.v;
  const std::int64_t adv = dv < 0 ? -dv : dv;
  const std::int64_t sv = dv < 0 ? -1 : 1;
  if (du >= adv) {
    if (du == 0) {
      if (w.contains(a.u, a.v)) plot(a.u, a.v);
      return;
    }
    // Major axis u: cell i is (a.u + i, a.v + sv * m) with m the integer nearest to i * adv / du,
    // ties down (toward a): m = ceil((2 i adv - du) / (2 du)), numerator + du - 1 >= 0.
    const std::int64_t i0 = std::max<std::int64_t>(0, w.u0 - a.u);
    const std::int64_t i1 = std::min<std::int64_t>(du, w.u0 + w.width - 1 - a.u);
    for (std::int64_t i = i0; i <= i1; ++i) {
      const std::int64_t v = a.v + sv * ((2 * i * adv + du - 1) / (2 * du));
      if (v >= w.v0 && v < w.v0 + w.height) plot(a.u + i, v);
    }
  } else {
    // Major axis v (adv > du >= 0): walk v from a.v by sv; u is nearest to i * du / adv, ties
    // toward a (the left endpoint).
    std::int64_t i0 = 0, i1 = adv;
    if (sv > 0) {
      i0 = std::max<std::int64_t>(0, w.v0 - a.v);
      i1 = std::min<std::int64_t>(adv, w.v0 + w.height - 1 - a.v);
    } else {
      i0 = std::max<std::int64_t>(0, a.v - (w.v0 + w.height - 1));
      i1 = std::min<std::int64_t>(adv, a.v - w.v0);
    }
    for (std::int64_t i = i0; i <= i1; ++i) {
      const std::int64_t u = a.u + (2 * i * du + adv - 1) / (2 * adv);
      if (u >= w.u0 && u < w.u0 + w.width) plot(u, a.v + sv * i);
    }
  }
}

/// Calls plot(u, v) for each cell of the polyline inside the window.
template <class Plot>
void for_each_polyline_cell(std::span<const Pixel> points, const Window& w, Plot&& plot) {
  if (points.size() == 1) {
    if (w.contains(points[0].u, points[0].v)) plot(points[0].u, points[0].v);
    return;
  }
  for (std::size_t i = 1; i < points.size(); ++i) for_each_line_cell(points[i - 1], points[i], w, plot);
}

/// Calls plot(u, v) for each cell of a closed ring's outline inside the window (the closing edge
/// is implied when the ring does not repeat its first vertex).
template <class Plot>
void for_each_ring_cell(std::span<const Pixel> ring, const Window& w, Plot&& plot) {
  if (ring.empty()) return;
  for_each_polyline_cell(ring, w, plot);
  if (ring.size() > 2 && !(ring.front() == ring.back())) for_each_line_cell(ring.back(), ring.front(), w, plot);
}

/// Reusable scratch space of the polygon filler (one per thread).
struct PolygonScratch {
  std::vector<std::vector<double>> crossings;  ///< per window row
};

/// Calls plot(u, v) for each cell of the polygon (rings under even-odd, outlines included)
/// inside the window. Each ring is a closed sequence; the closing edge is implied.
template <class Plot>
void for_each_polygon_cell(std::span<const std::vector<Pixel>> rings, const Window& w, PolygonScratch& scratch,
                           Plot&& plot) {
  auto& rows = scratch.crossings;
  if (rows.size() < static_cast<std::size_t>(w.height)) rows.resize(static_cast<std::size_t>(w.height));
  for (std::int64_t r = 0; r < w.height; ++r) rows[static_cast<std::size_t>(r)].clear();
  bool any = false;
  for (const auto& ring : rings) {
    const std::size_t n = ring.size();
    for (std::size_t i = 0; i < n; ++i) {
      const Pixel p = ring[i];
      const Pixel q = ring[(i + 1) % n];
      if (p.v == q.v) continue;
      const Pixel lo = p.v < q.v ? p : q;
      const Pixel hi = p.v < q.v ? q : p;
      // The edge crosses the centre rows v with lo.v <= v < hi.v (half-open: a vertex is counted once).
      const std::int64_t r0 = std::max(lo.v, w.v0);
      const std::int64_t r1 = std::min(hi.v, w.v0 + w.height);
      if (r0 >= r1) continue;
      const double slope = static_cast<double>(hi.u - lo.u) / static_cast<double>(hi.v - lo.v);
      for (std::int64_t v = r0; v < r1; ++v) {
        rows[static_cast<std::size_t>(v - w.v0)].push_back(static_cast<double>(lo.u) +
                                                           static_cast<double>(v - lo.v) * slope);
      }
      any = true;
    }
  }
  if (any) {
    for (std::int64_t r = 0; r < w.height; ++r) {
      auto& xs = rows[static_cast<std::size_t>(r)];
      if (xs.size() < 2) continue;
      std::sort(xs.begin(), xs.end());
      for (std::size_t k = 0; k + 1 < xs.size(); k += 2) {
        // Centres u with xs[k] <= u < xs[k + 1].
        const std::int64_t first = std::max(static_cast<std::int64_t>(std::ceil(xs[k])), w.u0);
        const std::int64_t last = std::min(static_cast<std::int64_t>(std::ceil(xs[k + 1])) - 1, w.u0 + w.width - 1);
        for (std::int64_t u = first; u <= last; ++u) plot(u, w.v0 + r);
      }
    }
  }
  for (const auto& ring : rings) for_each_ring_cell(std::span<const Pixel>(ring), w, plot);
}

}  // namespace seqloc::raster
