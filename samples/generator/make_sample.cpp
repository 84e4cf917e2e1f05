// Writes the synthetic regions of our own: the rural valley of samples/ (farmland and forest
// crossed by a winding road, with a T intersection, tracks, a farm and a hamlet) and, for
// development draws that no report uses, a mountain pass whose roads see few features (a
// serpentine of long legs between forest patches, three tracks, a hamlet in the valley).
// Everything is placed by formulas and fixed-seed generators of our own, so a file is the same on
// every machine.
//
//   seqloc-make-sample [--region rural-valley|mountain-pass] OUTPUT.osm.pbf

#include <algorithm>
#include <array>
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

void build_rural_valley(SyntheticMap& map) {
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

// The mountain pass: a serpentine of six legs 190 m apart, each 1.11 km long, joined by hairpins,
// climbing from a valley road along a river. Between the legs, forest patches of random extent
// come within 8 to 12 m of the road (their ends are what a camera sees along a leg); a few
// trees, benches, a parking place and a retaining wall; three tracks. Like the feature-sparse
// regions the camera sees road and forest edges parallel to it for most of a leg.
constexpr double kLegHalf = 555, kLegStep = 190, kLegFirst = -500, kHairpin = kLegStep / 2;
constexpr int kLegs = 6;

double leg_y(int leg, double x) {
  const double m = 3 + leg % 2;  // whole half-waves: the wiggle vanishes at the hairpins
  return kLegFirst + kLegStep * leg + 12.0 * std::sin(seqloc::core::kPi * m * (x + kLegHalf) / (2 * kLegHalf));
}

// The serpentine as one way; returns its legs' node ids (for the tracks and the valley's link).
std::vector<std::vector<std::int64_t>> serpentine(SyntheticMap& map) {
  std::vector<std::vector<std::int64_t>> legs(kLegs);
  std::vector<std::int64_t> all;
  for (int leg = 0; leg < kLegs; ++leg) {
    const bool east = leg % 2 == 0;
    for (int i = 0; i <= 2 * static_cast<int>(kLegHalf) / 15; ++i) {
      const double x = east ? -kLegHalf + 15.0 * i : kLegHalf - 15.0 * i;
      legs[leg].push_back(map.node({x, leg_y(leg, x)}));
      all.push_back(legs[leg].back());
    }
    if (leg + 1 == kLegs) break;
    const double cx = east ? kLegHalf : -kLegHalf, cy = kLegFirst + kLegStep * leg + kHairpin;
    for (int k = 1; k < 12; ++k) {  // the hairpin: a half circle outwards, 15 degrees a node
      const double a = -seqloc::core::kPi / 2 + seqloc::core::kPi * k / 12;
      all.push_back(map.node({cx + (east ? 1 : -1) * kHairpin * std::cos(a), cy + kHairpin * std::sin(a)}));
    }
  }
  map.way_through(all, {{"highway", "secondary"}, {"name", "Passstrasse"}});
  return legs;
}

// A forest patch above a leg from x0 to x1, its edges `gap` metres off the leg and the next.
void forest_between(SyntheticMap& map, int leg, double x0, double x1, double gap) {
  std::vector<LocalPoint> ring;
  for (double x = x0; x <= x1; x += 30) ring.push_back({x, leg_y(leg, x) + gap});
  for (double x = x1; x >= x0; x -= 30) {
    ring.push_back({x, leg < kLegs - 1 ? leg_y(leg + 1, x) - gap : leg_y(leg, x) + 120});
  }
  map.way(ring, {{"landuse", "forest"}}, true);
}

void valley(SyntheticMap& map, std::int64_t serpentine_start, Random& rng) {
  std::vector<std::int64_t> road;
  std::int64_t junction = 0;
  auto valley_y = [](double x) { return -640.0 + 15.0 * std::sin(x / 120.0); };
  for (int x = -720; x <= 720; x += 15) {
    road.push_back(map.node({static_cast<double>(x), valley_y(x)}));
    if (x == -615) junction = road.back();
  }
  map.way_through(road, {{"highway", "primary"}, {"name", "Talstrasse"}});
  std::vector<std::int64_t> link{junction};
  for (int k = 1; k < 8; ++k) {
    const double t = k / 8.0;
    const double y = valley_y(-615) * (1 - t) + kLegFirst * t - 20 * std::sin(seqloc::core::kPi * t);
    link.push_back(map.node({-615 + (615 - kLegHalf) * t, y}));
  }
  link.push_back(serpentine_start);
  map.way_through(link, {{"highway", "unclassified"}});
  std::vector<LocalPoint> river;
  for (double x = -740; x <= 740; x += 40) river.push_back({x, valley_y(x) - 30 - 4 * std::sin(x / 35)});
  for (double x = 740; x >= -740; x -= 40) river.push_back({x, valley_y(x) - 48 + 3 * std::sin(x / 45)});
  map.way(river, {{"natural", "water"}}, true);
  for (int k = 0; k < 5; ++k) {  // the hamlet at the junction
    const double x = -680 + 30 * k;
    map.way(rectangle(x, valley_y(x) + 24 + rng.uniform(0, 8), rng.uniform(9, 13), rng.uniform(8, 11),
                      rng.uniform(-10, 10)),
            {{"building", "house"}}, true);
  }
  map.node({-600, valley_y(-600) - 6}, {{"highway", "bus_stop"}});
}

// Tracks up the slope from legs 0, 2 and 4 (eastbound), a gate on the second.
void tracks(SyntheticMap& map, const std::vector<std::vector<std::int64_t>>& legs, Random& rng) {
  for (int k = 0; k < 3; ++k) {
    const auto& nodes = legs[2 * k];
    const auto at = nodes.size() / 4 + static_cast<std::size_t>(rng.uniform(0, static_cast<double>(nodes.size()) / 2));
    const double x = -kLegHalf + 15.0 * static_cast<double>(at), y = leg_y(2 * k, x);
    const std::int64_t second = map.node({x + 20, y + 40}, k == 1 ? Tags{{"barrier", "gate"}} : Tags{});
    map.way_through({nodes[at], second, map.node({x + 70, y + 120}), map.node({x + 60, y + 170})},
                    {{"highway", "track"}});
  }
}

void build_mountain_pass(SyntheticMap& map) {
  Random rng(20261207);
  const auto legs = serpentine(map);
  valley(map, legs.front().front(), rng);
  map.way({{-kLegHalf, leg_y(kLegs - 1, -kLegHalf)}, {-600, 600}, {-640, 720}}, {{"highway", "unclassified"}});
  for (int leg = 0; leg < kLegs; ++leg) {  // two forest patches above each leg, apart
    const double a0 = rng.uniform(-500, -200), a1 = a0 + rng.uniform(150, 350);
    const double b0 = rng.uniform(a1 + 60, 250), b1 = b0 + rng.uniform(150, 300);
    forest_between(map, leg, a0, a1, rng.uniform(8, 12));
    forest_between(map, leg, b0, std::min(b1, 520.0), rng.uniform(8, 12));
  }
  tracks(map, legs, rng);
  const double hairpin_y = kLegFirst + kHairpin;  // the first hairpin's centre; the k-th is kLegStep * k above
  map.way(rectangle(kLegHalf + kHairpin + 18, hairpin_y, 22, 30, 0), {{"amenity", "parking"}}, true);
  map.node({-kLegHalf - kHairpin - 6, hairpin_y + kLegStep}, {{"amenity", "bench"}});
  map.node({kLegHalf + kHairpin + 6, hairpin_y + 4 * kLegStep}, {{"amenity", "bench"}});
  const double wall_y = hairpin_y + 3 * kLegStep;
  map.way({{-kLegHalf - 30, wall_y - 60}, {-kLegHalf - kHairpin + 6, wall_y}, {-kLegHalf - 30, wall_y + 60}},
          {{"barrier", "retaining_wall"}});
  for (int k = 0; k < 16; ++k) {  // lone trees by the legs
    const int leg = k % kLegs;
    const double x = rng.uniform(-500, 500);
    map.node({x, leg_y(leg, x) + (k % 2 ? 1 : -1) * rng.uniform(6, 14)}, {{"natural", "tree"}});
  }
}

// The regions the generator writes, each around its own origin.
struct Region {
  const char* name;
  double lat0_deg, lon0_deg;
  void (*build)(SyntheticMap&);
};
constexpr std::array kRegions{Region{"rural-valley", 47.95, 11.25, build_rural_valley},
                              Region{"mountain-pass", 46.62, 10.45, build_mountain_pass}};

}  // namespace

int main(int argc, char** argv) {
  const std::string usage =
      "usage: seqloc-make-sample [--region rural-valley|mountain-pass] OUTPUT.osm.pbf\n"
      "Writes a synthetic region of our own: rural-valley (the default) is samples/'s; mountain-pass, a\n"
      "serpentine between forest patches that sees few features, is for development draws.\n";
  std::vector<std::string> args(argv + 1, argv + argc);
  if (args.size() == 1 && args[0] == "--help") {
    std::fputs(usage.c_str(), stdout);
    return 0;
  }
  std::string name = kRegions.front().name;
  if (args.size() == 3 && args[0] == "--region") {
    name = args[1];
    args.erase(args.begin(), args.begin() + 2);
  }
  const auto* region = std::find_if(kRegions.begin(), kRegions.end(), [&](const Region& r) { return name == r.name; });
  if (args.size() != 1 || region == kRegions.end()) {
    std::fputs(usage.c_str(), stderr);
    return 2;
  }
  try {
    SyntheticMap map(region->lat0_deg, region->lon0_deg);
    region->build(map);
    map.write(args[0], 30);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "seqloc-make-sample: error: %s\n", e.what());
    return 1;
  }
  return 0;
}
