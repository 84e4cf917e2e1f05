#include "seqloc/sim/simulate.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <fstream>
#include <iomanip>
#include <locale>
#include <map>
#include <random>
#include <stdexcept>

#include <nlohmann/json.hpp>

#include "seqloc/core/angles.hpp"
#include "seqloc/core/error.hpp"
#include "seqloc/core/files.hpp"
#include "seqloc/core/flat_index.hpp"
#include "seqloc/core/units.hpp"
#include "seqloc/io/route.hpp"
#include "seqloc/osm/classes.hpp"

namespace seqloc::sim {
namespace {

using core::kCellM;
constexpr int kAttempts = 500;       // tries at a route before giving up
constexpr double kEdgeMarginM = 40;  // routes keep this far from the region's edge
constexpr double kMaxTurnDeg = 100;  // largest heading change between two frames

void require(bool ok, const std::string& what) {
  if (!ok) throw UsageError("simulate: " + what);
}

// The road network as an undirected graph on the centerlines' vertices (shared OSM nodes project
// to identical coordinates, which is how ways meet at junctions).
struct RoadGraph {
  std::vector<osm::GridPoint> nodes;
  std::vector<std::vector<int>> next;
  std::vector<std::array<int, 2>> edges;

  explicit RoadGraph(const std::vector<raster::RoadLine>& roads) {
    std::map<std::pair<std::int64_t, std::int64_t>, int> id;
    auto node = [&](const osm::GridPoint& p) {
      const std::pair key{std::llround(p.x_m * 100), std::llround(p.y_m * 100)};
      const auto [it, added] = id.emplace(key, static_cast<int>(nodes.size()));
      if (added) {
        nodes.push_back(p);
        next.emplace_back();
      }
      return it->second;
    };
    for (const auto& road : roads) {
      for (std::size_t i = 1; i < road.points.size(); ++i) {
        const int a = node(road.points[i - 1]), b = node(road.points[i]);
        if (a == b) continue;
        next[static_cast<std::size_t>(a)].push_back(b);
        next[static_cast<std::size_t>(b)].push_back(a);
        edges.push_back({a, b});
      }
    }
  }
  [[nodiscard]] const osm::GridPoint& at(int i) const { return nodes[static_cast<std::size_t>(i)]; }
};

double grid_heading(const osm::GridPoint& a, const osm::GridPoint& b) {
  return core::wrap360(std::atan2(b.x_m - a.x_m, b.y_m - a.y_m) * core::kRadToDeg);
}

// A walk along the network, straight on at most junctions, turning sometimes; never a U-turn.
// Independent random streams: one per route (its path, its first GPS error) and one per frame
// (GPS drift, camera error, perception noise), each seeded from (seed, route, frame). What a frame
// draws never depends on what earlier frames or routes drew, so two runs that differ in one
// frame's view (a map edit, a fix of the rasterizer) differ in that frame only, and variants of
// the method are compared on the same noise.
constexpr std::uint32_t kRouteStream = 0xFFFFFFFFu;

std::mt19937_64 noise_stream(std::uint64_t seed, int route, std::uint32_t frame) {
  std::seed_seq sequence{static_cast<std::uint32_t>(seed), static_cast<std::uint32_t>(seed >> 32),
                         static_cast<std::uint32_t>(route), frame};
  return std::mt19937_64(sequence);
}

std::vector<int> walk(const RoadGraph& graph, double length_m, std::mt19937_64& rng) {
  std::uniform_int_distribution<std::size_t> pick_edge(0, graph.edges.size() - 1);
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  const auto& e = graph.edges[pick_edge(rng)];
  std::vector<int> path = uniform(rng) < 0.5 ? std::vector<int>{e[0], e[1]} : std::vector<int>{e[1], e[0]};
  double driven =
      std::hypot(graph.at(path[1]).x_m - graph.at(path[0]).x_m, graph.at(path[1]).y_m - graph.at(path[0]).y_m);
  while (driven < length_m) {
    const int prev = path[path.size() - 2], here = path.back();
    const double in = grid_heading(graph.at(prev), graph.at(here));
    std::vector<std::pair<double, int>> options;  // |turn|, node
    for (int n : graph.next[static_cast<std::size_t>(here)]) {
      if (n == prev) continue;
      const double turn = std::abs(core::wrap180(grid_heading(graph.at(here), graph.at(n)) - in));
      if (turn < 100) options.emplace_back(turn, n);
    }
    if (options.empty()) return {};  // a dead end: this attempt fails
    std::sort(options.begin(), options.end());
    std::size_t pick = 0;  // straight on, or now and then one of the other branches
    if (options.size() > 1 && uniform(rng) >= 0.7)
      pick = std::uniform_int_distribution<std::size_t>(1, options.size() - 1)(rng);
    const int chosen = options[pick].second;
    driven += std::hypot(graph.at(chosen).x_m - graph.at(here).x_m, graph.at(chosen).y_m - graph.at(here).y_m);
    path.push_back(chosen);
  }
  return path;
}

// Poses every U(min, max) metres along the path, headings along the segment.
std::vector<GridPose> sample_poses(const RoadGraph& graph, const std::vector<int>& path, const SimulateOptions& o,
                                   std::mt19937_64& rng) {
  std::uniform_real_distribution<double> spacing(o.min_spacing_m, o.max_spacing_m);
  std::vector<GridPose> poses;
  double target = 0, start = 0;  // arc length of the next pose; of the current segment's start
  for (std::size_t i = 1; i < path.size() && static_cast<int>(poses.size()) < o.frames; ++i) {
    const auto& a = graph.at(path[i - 1]);
    const auto& b = graph.at(path[i]);
    const double length = std::hypot(b.x_m - a.x_m, b.y_m - a.y_m);
    while (target <= start + length && static_cast<int>(poses.size()) < o.frames) {
      const double f = (target - start) / length;
      poses.push_back({a.x_m + f * (b.x_m - a.x_m), a.y_m + f * (b.y_m - a.y_m), grid_heading(a, b)});
      target += spacing(rng);
    }
    start += length;
  }
  return poses;
}

int poisson(double mean, std::mt19937_64& rng) {
  if (mean <= 0) return 0;
  return std::poisson_distribution<int>(mean)(rng);
}

// Perception's failures on a clean observation (ObservationModel's fields, in that order).
void corrupt(io::Observation& obs, const ObservationModel& m, std::mt19937_64& rng) {
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  for (std::size_t c = 0; c < 3; ++c) {
    std::vector<char> seen(256, 0), missed(256, 0);
    for (std::size_t i = 0; i < obs.cells(); ++i) {
      if (obs.visible[i]) seen[obs.classes[3 * i + c]] = 1;
    }
    for (std::size_t code = 1; code < 256; ++code)
      missed[code] = static_cast<char>(seen[code] && uniform(rng) < m.class_miss);
    for (std::size_t i = 0; i < obs.cells(); ++i) {
      std::uint8_t& v = obs.classes[3 * i + c];
      if (v != 0 && (missed[v] || uniform(rng) < m.cell_dropout)) v = 0;
    }
  }
  const int t = obs.size;
  const int blobs = poisson(m.spurious_blobs, rng);
  for (int b = 0; b < blobs; ++b) {
    const auto channel = static_cast<std::size_t>(std::min(2.0, std::floor(uniform(rng) * 3)));
    const int classes = static_cast<int>(osm::group_names(static_cast<osm::Channel>(channel)).size());
    const auto code = static_cast<std::uint8_t>(1 + std::min(classes - 1, static_cast<int>(uniform(rng) * classes)));
    const double r0 = uniform(rng) * (t - 1), c0 = uniform(rng) * (t - 1);
    // Areas are discs of 1-3 m, ways segments of 4-12 m, nodes single cells.
    const double radius = channel == 0 ? (1 + 2 * uniform(rng)) / kCellM : 0;
    const double length = channel == 1 ? (4 + 8 * uniform(rng)) / kCellM : 0;
    const double dir = uniform(rng) * 2 * core::kPi;
    auto paint = [&](int r, int c) {
      if (r < 0 || r >= t || c < 0 || c >= t) return;
      const std::size_t i = core::flat(r, c, t);
      if (obs.visible[i]) obs.classes[3 * i + channel] = code;
    };
    if (channel == 1) {
      // Half-cell steps, counted in integers (0.5 is exact, so the points are the same).
      const auto steps = static_cast<int>(std::floor(length / 0.5));
      for (int k = 0; k <= steps; ++k) {
        const double s = 0.5 * k;
        paint(static_cast<int>(std::lround(r0 + s * std::cos(dir))),
              static_cast<int>(std::lround(c0 + s * std::sin(dir))));
      }
    } else {
      const int reach = static_cast<int>(std::ceil(radius));
      for (int dr = -reach; dr <= reach; ++dr) {
        for (int dc = -reach; dc <= reach; ++dc) {
          if (dr * dr + dc * dc <= radius * radius) paint(static_cast<int>(r0) + dr, static_cast<int>(c0) + dc);
        }
      }
    }
  }
}

// v to `digits` decimals, as the text of std::fixed would give it.
double rounded(double v, int digits) {
  std::ostringstream s;
  s.imbue(std::locale::classic());
  s << std::fixed << std::setprecision(digits) << v;
  const std::string text = s.str();
  double out = 0;
  std::from_chars(text.data(), text.data() + text.size(), out);
  return out;
}

}  // namespace

void ObservationModel::validate() const {
  require(range_m >= 2 && range_m <= 120, "camera range_m must be in [2, 120]");
  require(fov_deg > 0 && fov_deg <= 360, "camera fov_deg must be in (0, 360]");
  auto probability = [](double p) { return p >= 0 && p <= 1; };
  require(probability(class_miss) && probability(cell_dropout) && probability(wrong_frame),
          "class_miss, cell_dropout and wrong_frame are probabilities in [0, 1]");
  require(spurious_blobs >= 0 && spurious_blobs <= 100, "spurious_blobs must be in [0, 100]");
  require(jitter_m >= 0 && jitter_m <= 10 && jitter_deg >= 0 && jitter_deg <= 45,
          "jitter_m must be in [0, 10] and jitter_deg in [0, 45]");
}

int ObservationModel::side() const { return 2 * static_cast<int>(std::lround(range_m / kCellM)) + 1; }

void SimulateOptions::validate() const {
  require(routes >= 1 && routes <= 100000, "routes must be in [1, 100000]");
  require(frames >= 2 && frames <= 1000000, "frames must be in [2, 1000000]");
  require(min_spacing_m > 0 && max_spacing_m >= min_spacing_m && max_spacing_m <= 100,
          "spacing must satisfy 0 < min <= max <= 100 m");
  require(speed_mps > 0 && speed_mps <= 60, "speed_mps must be in (0, 60]");
  require(gps_error_m >= 0 && gps_error_m <= 1000 && gps_drift_m >= 0, "gps_error_m must be in [0, 1000], drift >= 0");
  require(crop_size >= 2 && crop_size % 2 == 0, "crop_size must be even");
  camera.validate();
}

io::Observation render_observation(raster::CacheReader& cache, const GridPose& pose, const ObservationModel& camera) {
  const int t = camera.side();
  const double centre = (t - 1) / 2.0;
  const double pu = cache.grid().region_u(pose.x), pv = cache.grid().region_v(pose.y);
  const int window = t + 4;
  const std::int64_t u0 = std::llround(pu) - window / 2, v0 = std::llround(pv) - window / 2;
  std::vector<std::uint8_t> map;
  cache.read_classes(u0, v0, window, window, map, /*fill_outside=*/true);
  auto cell = [&](double u, double v) -> const std::uint8_t* {
    const auto c = std::llround(u) - u0, r = std::llround(v) - v0;
    if (c < 0 || c >= window || r < 0 || r >= window) return nullptr;
    return map.data() + static_cast<std::size_t>(r * window + c) * 3;
  };
  const double th = pose.heading_deg * core::kDegToRad, s = std::sin(th), co = std::cos(th);
  const std::uint8_t building = osm::kBuildingArea.code();
  io::Observation obs(t);
  for (int r = 0; r < t; ++r) {
    for (int c = 0; c < t; ++c) {
      const double f = (centre - r) * kCellM, rt = (c - centre) * kCellM;  // forward, right (m)
      if (f * f + rt * rt > camera.range_m * camera.range_m) continue;
      if (camera.fov_deg < 360 && std::abs(std::atan2(rt, f)) * core::kRadToDeg > camera.fov_deg / 2) continue;
      const double e = f * s + rt * co, n = f * co - rt * s;  // east, north (m)
      const double tu = pu + e / kCellM, tv = pv - n / kCellM;
      const std::uint8_t* target = cell(tu, tv);
      if (!target) continue;
      if (camera.occlusion) {
        // March from the camera; a building cell before the target hides it.
        const double cells = std::hypot(e, n) / kCellM;
        const int steps = static_cast<int>(std::ceil(cells * 2));
        bool hidden = false;
        for (int k = 1; k < steps && !hidden; ++k) {
          const double a = static_cast<double>(k) / steps;
          const double su = pu + a * (tu - pu), sv = pv + a * (tv - pv);
          if (std::llround(su) == std::llround(tu) && std::llround(sv) == std::llround(tv)) break;
          const std::uint8_t* p = cell(su, sv);
          hidden =
              p && p[0] == building && !(std::llround(su) == std::llround(pu) && std::llround(sv) == std::llround(pv));
        }
        if (hidden) continue;
      }
      const std::size_t i = core::flat(r, c, t);
      obs.visible[i] = 1;
      std::copy_n(target, 3, obs.classes.data() + 3 * i);
    }
  }
  return obs;
}

namespace {

// A path along the roads of options.frames poses, inside the region by kEdgeMarginM and with no
// turn between frames sharper than odometry's plausibility limit. Throws after kAttempts tries.
std::vector<GridPose> drive(const RoadGraph& graph, raster::CacheReader& cache, const SimulateOptions& options,
                            std::mt19937_64& rng) {
  const auto& grid = cache.grid();
  auto inside = [&](const GridPose& p) {
    return p.x > grid.min_x() + kEdgeMarginM && p.x < grid.max_x() - kEdgeMarginM &&
           p.y > grid.min_y() + kEdgeMarginM && p.y < grid.max_y() - kEdgeMarginM;
  };
  const double length = options.frames * options.max_spacing_m + 10;
  for (int attempt = 0; attempt < kAttempts; ++attempt) {
    const auto path = walk(graph, length, rng);
    if (path.empty()) continue;
    auto poses = sample_poses(graph, path, options, rng);
    bool ok = static_cast<int>(poses.size()) >= options.frames && std::all_of(poses.begin(), poses.end(), inside);
    for (std::size_t i = 1; ok && i < poses.size(); ++i) {
      ok = std::abs(core::wrap180(poses[i].heading_deg - poses[i - 1].heading_deg)) <= kMaxTurnDeg;
    }
    if (ok) return poses;
  }
  std::ostringstream s;
  s << cache.path().string() << ": no road path of " << options.frames << " frames (about "
    << std::lround(options.frames * (options.min_spacing_m + options.max_spacing_m) / 2)
    << " m without dead ends or U-turns) found inside the region in " << kAttempts << " tries";
  throw DataError(s.str());
}

// One route being recorded: its poses, the crop centre's error (a bounded random walk) and the clock.
struct Recording {
  std::vector<GridPose> poses;
  double error_x = 0, error_y = 0;
  double timestamp = 0;
};

// Frame i of route r: what the camera saw (written under dir/observations), the odometry from
// frame i - 1, the crop centre off by the GPS error, the truth; recorded as a GPS receiver and an
// odometer would report them (mm, 1e-4 m and degrees, 1e-9 degrees of lat/lon).
io::RouteFrame record_frame(raster::CacheReader& cache, const osm::RegionProjection& projection,
                            const SimulateOptions& options, int r, std::size_t i, Recording& rec,
                            const std::filesystem::path& dir) {
  const GridPose& p = rec.poses[i];
  std::mt19937_64 rng = noise_stream(options.seed, r, static_cast<std::uint32_t>(i));
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  std::normal_distribution<double> normal(0.0, 1.0);
  if (i > 0) {
    rec.error_x += options.gps_drift_m * normal(rng);
    rec.error_y += options.gps_drift_m * normal(rng);
    const double norm = std::hypot(rec.error_x, rec.error_y);
    if (norm > options.gps_error_m) {
      rec.error_x *= options.gps_error_m / norm;
      rec.error_y *= options.gps_error_m / norm;
    }
  }
  // What the camera saw: another place now and then, else here with a small pose error.
  GridPose seen = p;
  if (uniform(rng) < options.camera.wrong_frame) {
    const auto n = rec.poses.size();
    seen = rec.poses[static_cast<std::size_t>(uniform(rng) * static_cast<double>(n)) % n];
    seen.x += 60 * (uniform(rng) - 0.5);
    seen.y += 60 * (uniform(rng) - 0.5);
    seen.heading_deg = 360 * uniform(rng);
  } else {
    seen.x += options.camera.jitter_m * normal(rng);
    seen.y += options.camera.jitter_m * normal(rng);
    seen.heading_deg = core::wrap360(seen.heading_deg + options.camera.jitter_deg * normal(rng));
  }
  io::Observation obs = render_observation(cache, seen, options.camera);
  corrupt(obs, options.camera, rng);
  std::ostringstream frame;
  frame << std::setw(6) << std::setfill('0') << i;
  io::write_observation(dir / "observations" / (frame.str() + ".png"), obs);

  double odo_f = 0, odo_l = 0, odo_yaw = 0;
  if (i > 0) {
    const GridPose& q = rec.poses[i - 1];
    const double dx = p.x - q.x, dy = p.y - q.y, th = q.heading_deg * core::kDegToRad;
    odo_f = dx * std::sin(th) + dy * std::cos(th);
    odo_l = -dx * std::cos(th) + dy * std::sin(th);
    odo_yaw = core::wrap180(q.heading_deg - p.heading_deg);
    rec.timestamp += std::hypot(dx, dy) / options.speed_mps;
  }
  double gamma = 0;
  const osm::GeoPoint truth = projection.reverse({p.x, p.y}, gamma);
  const osm::GeoPoint fix = projection.reverse({p.x + rec.error_x, p.y + rec.error_y});
  io::RouteFrame f;
  f.frame = frame.str();
  f.timestamp_s = rounded(rec.timestamp, 3);
  f.observation = dir / "observations" / (frame.str() + ".png");
  f.crop_grid = osm::GridPoint{rounded(p.x + rec.error_x, 3), rounded(p.y + rec.error_y, 3)};
  f.odometry = {rounded(odo_f, 4), rounded(odo_l, 4), rounded(odo_yaw, 4)};
  if (i == 0) {
    f.gps = io::GpsPrior{{rounded(fix.lat_deg, 9), rounded(fix.lon_deg, 9)},
                         rounded(std::max(1.0, options.gps_error_m), 1)};
  }
  f.truth = io::GroundTruth{{rounded(truth.lat_deg, 9), rounded(truth.lon_deg, 9)},
                            rounded(core::wrap360(p.heading_deg + gamma), 4)};
  return f;
}

}  // namespace

void simulate_routes(raster::CacheReader& cache, const SimulateOptions& options, const std::filesystem::path& out,
                     const std::function<void(int, int)>& progress) {
  options.validate();
  const RoadGraph graph(cache.roads());
  if (graph.edges.empty()) throw DataError(cache.path().string() + ": the cache has no roads to drive along");
  const std::filesystem::path partial = core::staging_directory(out);
  std::filesystem::create_directories(partial);
  const auto projection = cache.metadata().projection();
  std::uniform_real_distribution<double> uniform(0.0, 1.0);
  for (int r = 0; r < options.routes; ++r) {
    std::mt19937_64 rng = noise_stream(options.seed, r, kRouteStream);  // the path and the first GPS error
    Recording rec{drive(graph, cache, options, rng)};
    std::ostringstream name;
    name << "route_" << std::setw(3) << std::setfill('0') << r;
    const auto dir = partial / name.str();
    std::filesystem::create_directories(dir / "observations");
    io::Route route;
    route.name = name.str();
    route.cell_m = kCellM;
    route.simulated_json = nlohmann::json{
        {"seed", options.seed},
        {"cache", cache.path().filename().string()},
        {"range_m", options.camera.range_m},
        {"fov_deg", options.camera.fov_deg},
        {"gps_error_m",
         options.gps_error_m}}.dump();
    // The crop centre's error starts uniform in the disc.
    const double a0 = uniform(rng) * 2 * core::kPi, r0 = options.gps_error_m * std::sqrt(uniform(rng));
    rec.error_x = r0 * std::cos(a0);
    rec.error_y = r0 * std::sin(a0);
    for (std::size_t i = 0; i < rec.poses.size(); ++i) {
      route.frames.push_back(record_frame(cache, projection, options, r, i, rec, dir));
    }
    io::write_route(route, dir);
    if (progress) progress(r + 1, options.routes);
  }
  // Into place: an old folder is replaced only once the new one is complete.
  core::commit_directory(partial, out);
}

}  // namespace seqloc::sim
