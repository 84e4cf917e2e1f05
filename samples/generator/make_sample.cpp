// Writes the synthetic rural region of samples/: a valley of farmland and forest crossed by a
// winding road, with a T intersection, tracks, a farm and a hamlet. Everything is placed by
// formulas and a fixed-seed generator of our own, so the file is the same on every machine.
//
//   seqloc-make-sample OUTPUT.osm.pbf

#include <cmath>
#include <cstdint>
#include <cstdio>
#include <exception>
#include <string>
#include <vector>

#include "seqloc/core/angles.hpp"
#include "seqloc/osm/synthetic.hpp"

namespace {

using seqloc::osm::LocalPoint;
using seqloc::osm::SyntheticMap;
using seqloc::osm::Tags;

// SplitMix64: a portable generator (std::uniform_*_distribution differ between libraries).
class Random {
 public:
  explicit Random(std::uint64_t seed) : state_(seed) {}
  double uniform(double lo, double hi) {
    std::uint64_t z = (state_ += 0x9E3779B97F4A7C15ull);
    z = (z ^ (z >> 30)) * 0xBF58476D1CE4E5B9ull;
    z = (z ^ (z >> 27)) * 0x94D049BB133111EBull;
    z ^= z >> 31;
    return lo + (hi - lo) * static_cast<double>(z >> 11) / 9007199254740992.0;
  }

 private:
  std::uint64_t state_;
};

std::vector<LocalPoint> rectangle(double x, double y, double w, double h, double angle_deg) {
  const double a = angle_deg * seqloc::core::kDegToRad, c = std::cos(a), s = std::sin(a);
  std::vector<LocalPoint> ring;
  for (auto [dx, dy] : {std::pair{-w / 2, -h / 2}, {w / 2, -h / 2}, {w / 2, h / 2}, {-w / 2, h / 2}}) {
    ring.push_back({x + c * dx - s * dy, y + s * dx + c * dy});
  }
  return ring;
}

// The main road: west to east, winding through the valley.
LocalPoint main_road(double x) { return {x, 60.0 * std::sin(x / 180.0) + 25.0 * std::sin(x / 53.0)}; }

void build(SyntheticMap& map) {
  Random rng(20261122);
  // Main road, shared node at the T intersection (x = 40).
  std::vector<std::int64_t> main_nodes;
  std::int64_t junction = 0;
  for (int x = -750; x <= 750; x += 15) {  // whole metres
    main_nodes.push_back(map.node(main_road(x)));
    if (x == 45) junction = main_nodes.back();
  }
  map.way_through(main_nodes, {{"highway", "secondary"}, {"name", "Talstrasse"}, {"maxspeed", "70"}});

  // The side road north to the hamlet, starting at the junction, curving.
  std::vector<std::int64_t> side{junction};
  const LocalPoint j = main_road(45);
  for (int t = 15; t <= 520; t += 15) {
    side.push_back(map.node({j.x_m + 40.0 * std::sin(t / 140.0), j.y_m + t}));
  }
  map.way_through(side, {{"highway", "unclassified"}, {"name", "Dorfweg"}});
  const LocalPoint hamlet{j.x_m + 40.0 * std::sin(520 / 140.0), j.y_m + 520};

  // Hamlet: a residential loop and houses along it, a bus stop, a bench, lamps, a post box.
  std::vector<LocalPoint> loop;
  for (int k = 0; k <= 24; ++k) {
    const double a = 2 * seqloc::core::kPi * k / 24;
    loop.push_back({hamlet.x_m + 90 * std::cos(a), hamlet.y_m + 60 + 60 * std::sin(a)});
  }
  map.way(loop, {{"highway", "residential"}});
  for (int k = 0; k < 10; ++k) {
    const double a = 2 * seqloc::core::kPi * (k + 0.5) / 10;
    const double r = 90 + 18;
    map.way(rectangle(hamlet.x_m + r * std::cos(a), hamlet.y_m + 60 + r * 0.7 * std::sin(a), rng.uniform(9, 14),
                      rng.uniform(8, 12), a * seqloc::core::kRadToDeg),
            {{"building", k % 4 == 0 ? "farm_auxiliary" : "house"}}, true);
  }
  map.node({hamlet.x_m + 6, hamlet.y_m - 8}, {{"highway", "bus_stop"}, {"name", "Talheim"}});
  map.node({hamlet.x_m + 8, hamlet.y_m - 10}, {{"amenity", "bench"}});
  map.node({hamlet.x_m - 5, hamlet.y_m + 2}, {{"amenity", "post_box"}});
  for (int k = 0; k < 6; ++k) map.node({hamlet.x_m - 6, hamlet.y_m - 100 + 30.0 * k}, {{"highway", "street_lamp"}});
  map.way(rectangle(hamlet.x_m + 20, hamlet.y_m + 60, 50, 35, 10), {{"leisure", "park"}}, true);
  map.way(rectangle(hamlet.x_m - 160, hamlet.y_m + 40, 30, 20, 0), {{"natural", "water"}}, true);

  // The farm south of the main road: buildings, a farmyard, a fenced paddock, hedges.
  const LocalPoint farm{-300, -170};
  map.way(rectangle(farm.x_m, farm.y_m, 90, 70, 8), {{"landuse", "farmyard"}}, true);
  map.way(rectangle(farm.x_m - 15, farm.y_m + 10, 22, 14, 8), {{"building", "farmhouse"}}, true);
  map.way(rectangle(farm.x_m + 20, farm.y_m - 12, 35, 18, 8), {{"building", "barn"}}, true);
  map.way(rectangle(farm.x_m + 25, farm.y_m + 22, 12, 10, 8), {{"building", "shed"}}, true);
  map.way(rectangle(farm.x_m - 110, farm.y_m - 20, 80, 60, 8), {{"barrier", "fence"}}, true);
  map.way({main_road(-300), {farm.x_m + 5, farm.y_m + 35}}, {{"highway", "service"}});
  map.way({{-700, -260}, {-420, -240}, {-150, -270}, {100, -250}}, {{"barrier", "hedge"}});
  map.way({{150, -120}, {160, -400}}, {{"natural", "tree_row"}});

  // Fields and meadows (farmland is no OrienterNet class: it stays background, as in reality).
  map.way({{-750, -300}, {-350, -280}, {-330, -600}, {-750, -600}}, {{"landuse", "farmland"}}, true);
  map.way({{-300, -300}, {140, -290}, {150, -600}, {-310, -600}}, {{"landuse", "meadow"}}, true);
  map.way({{180, -110}, {700, -150}, {720, -600}, {190, -600}}, {{"landuse", "farmland"}}, true);
  map.way({{-700, 120}, {-250, 140}, {-240, 420}, {-700, 400}}, {{"landuse", "meadow"}}, true);

  // The forest on the northern slope, with a clearing; a wood east of the hamlet.
  map.multipolygon({{{-750, 430}, {-200, 450}, {-80, 750}, {-750, 750}}},
                   {{{-520, 560}, {-420, 555}, {-410, 640}, {-515, 650}}}, {{"landuse", "forest"}});
  map.way({{300, 250}, {650, 200}, {720, 600}, {320, 700}}, {{"natural", "wood"}}, true);

  // Tracks: through the fields to the farm, and up into the forest.
  map.way({main_road(-600), {-620, -200}, {-560, -420}, {-420, -560}}, {{"highway", "track"}, {"tracktype", "grade2"}});
  map.way({main_road(-450), {-470, 250}, {-430, 480}, {-380, 720}}, {{"highway", "track"}});
  map.way({main_road(400), {420, 150}, {500, 400}, {480, 650}}, {{"highway", "track"}});
  map.way({{-430, 480}, {-300, 520}, {-200, 600}}, {{"highway", "path"}});

  // Scattered trees along the road and in the meadows.
  for (int k = 0; k < 60; ++k) {
    const double x = rng.uniform(-720, 720);
    const LocalPoint r = main_road(x);
    const double side_offset = (k % 2 ? 1 : -1) * rng.uniform(8, 40);
    map.node({r.x_m, r.y_m + side_offset}, {{"natural", "tree"}});
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2 || std::string(argv[1]) == "--help") {
    std::fprintf(stderr, "usage: seqloc-make-sample OUTPUT.osm.pbf\nWrites the synthetic rural sample region.\n");
    return argc == 2 ? 0 : 2;
  }
  try {
    SyntheticMap map(47.95, 11.25);
    build(map);
    map.write(argv[1], 30);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "seqloc-make-sample: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
