// Rasterization primitives: known geometry -> known cells, and window invariance (the property
// that makes tiles seamless).

#include <random>
#include <set>

#include <gtest/gtest.h>

#include "seqloc/raster/rasterize.hpp"

namespace seqloc::raster {
namespace {

using Cells = std::set<std::pair<std::int64_t, std::int64_t>>;

Cells line_cells(Pixel a, Pixel b, const Window& w = {-1000, -1000, 2000, 2000}) {
  Cells cells;
  for_each_line_cell(a, b, w, [&](std::int64_t u, std::int64_t v) { cells.emplace(u, v); });
  return cells;
}

Cells polygon_cells(const std::vector<std::vector<Pixel>>& rings, const Window& w = {-1000, -1000, 2000, 2000}) {
  Cells cells;
  PolygonScratch scratch;
  for_each_polygon_cell(std::span<const std::vector<Pixel>>(rings), w, scratch,
                        [&](std::int64_t u, std::int64_t v) { cells.emplace(u, v); });
  return cells;
}

TEST(Snap, PixelCentresAndTiesToEven) {
  // A point at the centre of cell (3, 4) has integral pixel coordinates (to_uv subtracts 0.5).
  EXPECT_EQ(snap(pixel_u(centre_x(3)), pixel_v(centre_y(4))), (Pixel{3, 4}));
  EXPECT_EQ(snap(2.5, -0.5), (Pixel{2, 0}));  // numpy rounds half to even
  EXPECT_EQ(snap(3.5, 1.5), (Pixel{4, 2}));
  // North-up: a point further north has a smaller row.
  EXPECT_LT(pixel_v(10.0), pixel_v(0.0));
}

TEST(Lines, AxisAlignedAndDiagonal) {
  EXPECT_EQ(line_cells({0, 0}, {3, 0}), (Cells{{0, 0}, {1, 0}, {2, 0}, {3, 0}}));
  EXPECT_EQ(line_cells({2, 5}, {2, 2}), (Cells{{2, 2}, {2, 3}, {2, 4}, {2, 5}}));
  EXPECT_EQ(line_cells({0, 0}, {3, 3}), (Cells{{0, 0}, {1, 1}, {2, 2}, {3, 3}}));
  EXPECT_EQ(line_cells({0, 0}, {3, -3}), (Cells{{0, 0}, {1, -1}, {2, -2}, {3, -3}}));
  // Shallow slope 1/4: the minor coordinate is the nearest to the exact line; at u = 2 the line
  // is half-way between rows 0 and 1 and the tie goes toward the left endpoint (0, 0).
  EXPECT_EQ(line_cells({0, 0}, {4, 1}), (Cells{{0, 0}, {1, 0}, {2, 0}, {3, 1}, {4, 1}}));
  EXPECT_EQ(line_cells({4, 1}, {0, 0}), (Cells{{0, 0}, {1, 0}, {2, 0}, {3, 1}, {4, 1}}));
  // Steep, left endpoint at the bottom: ties at v = 3 and v = 1 go toward (0, 4).
  EXPECT_EQ(line_cells({2, 0}, {0, 4}), (Cells{{0, 4}, {0, 3}, {1, 2}, {1, 1}, {2, 0}}));
  EXPECT_EQ(line_cells({7, 7}, {7, 7}), (Cells{{7, 7}}));
}

// The tie rule of conventions.md section 2 written out by brute force: at each step t of the
// major axis from the left endpoint L, try every cell across the minor axis and keep the one whose
// centre is nearest to the exact line; of two equally near, the one nearer to L's minor
// coordinate. Integer arithmetic only (distances scaled by the major extent).
Cells brute_force_line(Pixel a, Pixel b) {
  const Pixel left = (a.u < b.u || (a.u == b.u && a.v <= b.v)) ? a : b;
  const Pixel right = (left == a) ? b : a;
  const std::int64_t du = right.u - left.u, dv = right.v - left.v;
  const bool u_major = du >= std::abs(dv);
  const std::int64_t major = u_major ? du : std::abs(dv);
  const std::int64_t minor_delta = u_major ? dv : du;  // signed change of the minor coordinate
  const std::int64_t major_step = u_major ? 1 : (dv < 0 ? -1 : 1);
  Cells cells;
  for (std::int64_t t = 0; t <= major; ++t) {
    const std::int64_t minor0 = u_major ? left.v : left.u;
    // Exact minor coordinate = minor0 + t * minor_delta / major; compare c * major with it.
    const std::int64_t exact_scaled = minor0 * std::max<std::int64_t>(major, 1) + t * minor_delta;
    std::int64_t best = 0, best_distance = -1;
    for (std::int64_t c = minor0 - std::abs(minor_delta) - 1; c <= minor0 + std::abs(minor_delta) + 1; ++c) {
      const std::int64_t distance = std::abs(c * std::max<std::int64_t>(major, 1) - exact_scaled);
      const bool nearer = best_distance < 0 || distance < best_distance;
      const bool tie_toward_left = distance == best_distance && std::abs(c - minor0) < std::abs(best - minor0);
      if (nearer || tie_toward_left) {
        best = c;
        best_distance = distance;
      }
    }
    if (u_major) {
      cells.emplace(left.u + t, best);
    } else {
      cells.emplace(best, left.v + major_step * t);
    }
  }
  return cells;
}

TEST(Lines, TieRuleMatchesBruteForceInEveryOctantAndDirection) {
  // Every segment from the origin to a point of the 17 x 17 square around it (all eight octants,
  // the axes and the diagonals), each drawn in both directions and moved around the lattice so
  // that negative coordinates are covered too.
  int ties = 0;
  for (std::int64_t du = -8; du <= 8; ++du) {
    for (std::int64_t dv = -8; dv <= 8; ++dv) {
      for (const Pixel origin : {Pixel{0, 0}, Pixel{-13, 5}, Pixel{21, -34}}) {
        const Pixel a = origin, b{origin.u + du, origin.v + dv};
        const auto expected = brute_force_line(a, b);
        EXPECT_EQ(line_cells(a, b), expected) << a.u << "," << a.v << " -> " << b.u << "," << b.v;
        EXPECT_EQ(line_cells(b, a), expected) << b.u << "," << b.v << " -> " << a.u << "," << a.v;
      }
      const std::int64_t major = std::max(std::abs(du), std::abs(dv)), minor = std::min(std::abs(du), std::abs(dv));
      for (std::int64_t t = 1; t < major; ++t) ties += (2 * t * minor) % (2 * major) == major ? 1 : 0;
    }
  }
  EXPECT_GT(ties, 100) << "the square must hold many exact ties, or the test shows nothing";
}

TEST(Lines, SameCellsInBothDirectionsAndEightConnected) {
  std::mt19937 rng(7);
  std::uniform_int_distribution<int> d(-40, 40);
  for (int i = 0; i < 500; ++i) {
    const Pixel a{d(rng), d(rng)}, b{d(rng), d(rng)};
    const auto forward = line_cells(a, b);
    EXPECT_EQ(forward, line_cells(b, a));
    const auto span = std::max(std::abs(b.u - a.u), std::abs(b.v - a.v));
    EXPECT_EQ(static_cast<std::int64_t>(forward.size()), span + 1) << "one cell per major-axis step";
  }
}

TEST(Polygons, SquareIncludesItsOutline) {
  // Vertices at cell centres (0,0)-(4,3): interior centres by the half-open rule plus the drawn
  // outline give the closed 5 x 4 block, as OpenCV's fillPoly would.
  const auto cells = polygon_cells({{{0, 0}, {4, 0}, {4, 3}, {0, 3}}});
  Cells expected;
  for (int v = 0; v <= 3; ++v) {
    for (int u = 0; u <= 4; ++u) expected.emplace(u, v);
  }
  EXPECT_EQ(cells, expected);
}

TEST(Polygons, InnerRingCutsAHole) {
  const auto cells = polygon_cells({{{0, 0}, {10, 0}, {10, 10}, {0, 10}}, {{3, 3}, {7, 3}, {7, 7}, {3, 7}}});
  EXPECT_TRUE(cells.count({1, 1}));
  EXPECT_TRUE(cells.count({3, 5})) << "the hole's outline is drawn";
  EXPECT_FALSE(cells.count({5, 5})) << "the hole's inside is empty";
  EXPECT_FALSE(cells.count({11, 5}));
}

TEST(Polygons, TriangleAgainstPointInPolygonReference) {
  // Interior cells must be exactly the centres strictly inside the triangle (plus outline cells).
  const std::vector<Pixel> tri{{0, 0}, {40, 7}, {13, 31}};
  const auto cells = polygon_cells({tri});
  const auto outline = [&] {
    Cells c;
    for (std::size_t i = 0; i < 3; ++i) {
      auto l = line_cells(tri[i], tri[(i + 1) % 3]);
      c.insert(l.begin(), l.end());
    }
    return c;
  }();
  auto cross = [](Pixel a, Pixel b, double u, double v) {
    return (static_cast<double>(b.u - a.u)) * (v - static_cast<double>(a.v)) -
           (static_cast<double>(b.v - a.v)) * (u - static_cast<double>(a.u));
  };
  for (int v = -2; v < 35; ++v) {
    for (int u = -2; u < 45; ++u) {
      const double c0 = cross(tri[0], tri[1], u, v), c1 = cross(tri[1], tri[2], u, v), c2 = cross(tri[2], tri[0], u, v);
      const bool strictly_inside = (c0 > 0 && c1 > 0 && c2 > 0) || (c0 < 0 && c1 < 0 && c2 < 0);
      const bool drawn = cells.count({u, v}) > 0;
      if (strictly_inside) {
        EXPECT_TRUE(drawn) << u << "," << v;
      }
      if (!strictly_inside && !outline.count({u, v})) {
        // On-edge centres may go either way by the half-open rule; off-edge outside ones never.
        const bool on_edge = c0 == 0 || c1 == 0 || c2 == 0;
        if (!on_edge) {
          EXPECT_FALSE(drawn) << u << "," << v;
        }
      }
    }
  }
}

TEST(Windows, DrawingIsIndependentOfTheWindow) {
  std::mt19937 rng(11);
  std::uniform_int_distribution<int> d(-60, 60);
  for (int trial = 0; trial < 50; ++trial) {
    std::vector<std::vector<Pixel>> rings(2);
    for (auto& ring : rings) {
      for (int k = 0; k < 7; ++k) ring.push_back({d(rng), d(rng)});
    }
    const Window whole{-80, -80, 160, 160};
    const auto all_poly = polygon_cells(rings, whole);
    const auto all_line = line_cells(rings[0][0], rings[0][1], whole);
    // Four windows that tile the whole one.
    Cells poly, line;
    for (const Window w : {Window{-80, -80, 97, 61}, Window{17, -80, 63, 61}, Window{-80, -19, 97, 99},
                           Window{17, -19, 63, 99}}) {
      const auto p = polygon_cells(rings, w);
      poly.insert(p.begin(), p.end());
      const auto l = line_cells(rings[0][0], rings[0][1], w);
      line.insert(l.begin(), l.end());
      for (const auto& [u, v] : p) EXPECT_TRUE(w.contains(u, v));
    }
    EXPECT_EQ(poly, all_poly);
    EXPECT_EQ(line, all_line);
  }
}

}  // namespace
}  // namespace seqloc::raster
