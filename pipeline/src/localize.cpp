#include "seqloc/pipeline/localize.hpp"

#include <algorithm>
#include <cmath>
#include <cstring>
#include <iomanip>
#include <mutex>
#include <random>
#include <sstream>

#include <GeographicLib/Geodesic.hpp>

#include "seqloc/core/angles.hpp"
#include "seqloc/core/stopwatch.hpp"
#include "seqloc/core/thread_pool.hpp"
#include "seqloc/core/units.hpp"
#include "seqloc/filter/seqloc_filter.hpp"
#include "seqloc/io/npy.hpp"
#include "seqloc/io/observation.hpp"
#include "seqloc/matcher/calibration.hpp"
#include "seqloc/pipeline/frame_store.hpp"
#include "seqloc/pipeline/modes.hpp"
#include "seqloc/pipeline/region_catalog.hpp"
#include "seqloc/uncertainty/pose_uncertainty.hpp"

namespace seqloc::pipeline {

using core::kCellM;

GridCrop frame_crop(const io::RouteFrame& f, const raster::RegionGrid& grid, const osm::RegionProjection& projection) {
  GridCrop crop;
  if (f.crop_grid) {
    crop = {f.crop_grid->x_m, f.crop_grid->y_m, 0.0};
  } else {
    double gamma = 0;
    const auto g = projection.forward(*f.crop_geo, gamma);
    crop = {g.x_m, g.y_m, -gamma};  // true north is at grid heading -gamma
  }
  if (!f.observation.empty()) {
    crop.x = grid.min_x() + std::round((crop.x - grid.min_x()) / kCellM) * kCellM;
    crop.y = grid.max_y() - std::round((grid.max_y() - crop.y) / kCellM) * kCellM;
    crop.rotation_deg = 0;
  }
  return crop;
}

std::vector<float> match_frame(const io::RouteFrame& f, raster::CacheReader& cache,
                               const matcher::BevMatcher& matcher) {
  const io::Observation obs = io::read_observation(f.observation);
  const GridCrop crop = frame_crop(f, cache.grid(), cache.metadata().projection());
  // The crop centre is a cell corner: region pixel edges at integers.
  const int side = matcher.map_side(obs.size);
  const auto corner_u = std::llround(cache.grid().region_u(crop.x) + 0.5);
  const auto corner_v = std::llround(cache.grid().region_v(crop.y) + 0.5);
  std::vector<std::uint8_t> map;
  cache.read_classes(corner_u - side / 2, corner_v - side / 2, side, side, map, /*fill_outside=*/true);
  return matcher.match(obs, map);
}

std::vector<float> hwn_values(const filter::PreparedFrame& frame) {
  const std::size_t slice = static_cast<std::size_t>(frame.height) * static_cast<std::size_t>(frame.width);
  const auto N = static_cast<std::size_t>(frame.bins);
  std::vector<float> hwn(frame.log_prob.size());
  for (std::size_t j = 0; j < N; ++j)
    for (std::size_t c = 0; c < slice; ++c) hwn[c * N + j] = frame.log_prob[j * slice + c];
  return hwn;
}

filter::PreparedFrame prepare_volume(const filter::FrameVolume& volume, const LocalizeOptions& options) {
  const int threads = options.filter.threads;
  filter::PreparedFrame frame =
      filter::prepare_frame(volume, options.filter.headings, threads, 1.0 / options.volume_temperature);
  if (options.volume_calibration.identity()) return frame;
  // Blur and floor on the prepared frame where it lies ([bin][v][u]), then its log-softmax again.
  matcher::calibrate_heading_major(frame.log_prob, frame.bins, frame.height, frame.width, options.volume_calibration,
                                   threads);
  filter::normalize_frame(frame, threads);
  return frame;
}

namespace {

// route_frames with each frame's region cache given by `cache_of(i)` (the matcher scores a frame
// against its own region's classes).
FrameSource frames_from(const io::Route& route, std::function<raster::CacheReader&(std::size_t)> cache_of,
                        const LocalizeOptions& options) {
  auto matcher = std::make_shared<const matcher::BevMatcher>(options.matcher);
  auto prepared = [options](const filter::FrameVolume& volume) {  // a copy: the source may outlive the call
    return std::make_shared<const filter::PreparedFrame>(prepare_volume(volume, options));
  };
  return [&route, cache_of = std::move(cache_of), matcher, prepared](std::size_t i) {
    const io::RouteFrame& f = route.frames[i];
    if (f.observation.empty()) {
      const io::NpyVolume npy(f.volume);
      std::vector<unsigned char> transposed;
      const filter::FrameVolume volume = io::frame_volume(route, f, npy, transposed);
      try {
        return prepared(volume);
      } catch (const intake::IntakeError& e) {
        // The intake checks the values (NaN, infinities, negative probabilities); the user needs
        // to know which file holds them.
        throw DataError(f.volume.string() + " (frames.csv line " + std::to_string(f.line) + "): " + e.what());
      }
    }
    auto values = match_frame(f, cache_of(i), *matcher);
    const int size = matcher->config().size;
    const auto& calibration = matcher->config().calibration;
    if (!calibration.identity()) {
      matcher::calibrate_volume(values, size, size, matcher->config().headings, calibration, matcher->config().threads);
    }
    const filter::FrameVolume volume{values.data(),
                                     filter::VolumeType::float32,
                                     filter::VolumeValues::log_prob,
                                     size,
                                     size,
                                     matcher->config().headings,
                                     kCellM};
    return prepared(volume);
  };
}

}  // namespace

FrameSource route_frames(const io::Route& route, raster::CacheReader& cache, const LocalizeOptions& options) {
  return frames_from(
      route, [&cache](std::size_t) -> raster::CacheReader& { return cache; }, options);
}

FrameSource stored_route_frames(const io::Route& route, raster::CacheReader& cache, const LocalizeOptions& options,
                                int readers) {
  auto store = std::make_shared<FrameStore>(route_frames(route, cache, options), route.frames.size(), readers,
                                            options.frame_memory_mb << 20, options.spill_dir);
  return [store](std::size_t i) { return store->take(i); };
}

int frame_reads(io::Mode mode, const io::Route& route) {
  if (mode != io::Mode::smooth) return 1;
  const bool scored =
      std::any_of(route.frames.begin(), route.frames.end(), [](const io::RouteFrame& f) { return f.volume.empty(); });
  return scored ? 2 : 1;
}

void LocalizeOptions::validate() const {
  filter.validate();
  matcher.validate();
  if (!(volume_temperature > 0) || !std::isfinite(volume_temperature)) {
    std::ostringstream s;
    s << "localize options: volume_temperature = " << volume_temperature << ": must be finite and > 0";
    throw filter::FilterError(s.str());
  }
  volume_calibration.validate();
  if (!(max_crop_outside_m >= 0)) {
    std::ostringstream s;
    s << "localize options: max_crop_outside_m = " << max_crop_outside_m << ": must be >= 0";
    throw filter::FilterError(s.str());
  }
  if (!(max_crop_jump_m >= 0)) {
    std::ostringstream s;
    s << "localize options: max_crop_jump_m = " << max_crop_jump_m << ": must be >= 0 (0: the window's size)";
    throw filter::FilterError(s.str());
  }
  if (lag < 0) {
    std::ostringstream s;
    s << "localize options: lag = " << lag << ": must be >= 0 frames";
    throw filter::FilterError(s.str());
  }
  if (!(recentre_margin > 0 && recentre_margin < 0.5)) {
    std::ostringstream s;
    s << "localize options: recentre_margin = " << recentre_margin << ": must be in (0, 0.5)";
    throw filter::FilterError(s.str());
  }
}

void check_crops(const io::Route& route, const raster::RegionGrid& grid, const osm::RegionProjection& projection,
                 const LocalizeOptions& options) {
  const double max_jump_m = options.crop_jump_limit_m(), margin = options.max_crop_outside_m;
  const auto csv = (route.dir / "frames.csv").string();
  auto fail = [&](const io::RouteFrame& f, const std::string& what) {
    throw DataError(csv + ":" + std::to_string(f.line) + ": " + what);
  };
  auto inside = [&](double x, double y) {
    return std::isfinite(x) && std::isfinite(y) && x >= grid.min_x() - margin && x <= grid.max_x() + margin &&
           y >= grid.min_y() - margin && y <= grid.max_y() + margin;
  };
  const io::RouteFrame* previous = nullptr;
  GridCrop previous_crop;
  for (const auto& f : route.frames) {
    const GridCrop crop = frame_crop(f, grid, projection);
    if (!inside(crop.x, crop.y)) {
      std::ostringstream s;
      s.precision(7);
      if (f.crop_geo) {
        double metres = 0;
        GeographicLib::Geodesic::WGS84().Inverse(f.crop_geo->lat_deg, f.crop_geo->lon_deg, projection.lat0_deg(),
                                                 projection.lon0_deg(), metres);
        const double km = metres / 1000.0;
        s << "crop centre (crop_lat " << f.crop_geo->lat_deg << ", crop_lon " << f.crop_geo->lon_deg << ") lies "
          << std::setprecision(4) << km << " km from the region's centre, outside the region";
        const auto swapped = projection.forward(osm::GeoPoint{f.crop_geo->lon_deg, f.crop_geo->lat_deg});
        if (std::abs(f.crop_geo->lon_deg) <= 90 && inside(swapped.x_m, swapped.y_m)) {
          s << "; crop_lat and crop_lon look swapped";
        }
      } else {
        s << "crop centre (crop_x " << crop.x << ", crop_y " << crop.y << ") lies outside the region (" << std::fixed
          << std::setprecision(1) << "x in [" << grid.min_x() << ", " << grid.max_x() << "], y in [" << grid.min_y()
          << ", " << grid.max_y() << "] m in the region CRS)";
      }
      if (margin > 0) s << " by more than the allowed " << margin << " m (--max-crop-outside)";
      fail(f, s.str());
    }
    if (previous != nullptr) {
      const double jump = std::hypot(crop.x - previous_crop.x, crop.y - previous_crop.y);
      if (jump > max_jump_m) {
        std::ostringstream s;
        s.precision(1);
        s << std::fixed << "crop centre lies " << jump << " m from the previous frame's (line " << previous->line
          << "), more than the limit of " << max_jump_m
          << " m (the belief window's size unless --max-crop-jump says otherwise)";
        fail(f, s.str());
      }
    }
    previous = &f;
    previous_crop = crop;
  }
}

io::FramePose::Uncertainty uncertainty_of(const filter::BeliefVolume& belief, const filter::Pose& estimate,
                                          int threads) {
  const uncertainty::PoseUncertainty u = uncertainty::pose_uncertainty(belief, estimate, threads);
  return {u.cov_ee_m2, u.cov_en_m2, u.cov_nn_m2, u.heading_sd_deg, u.mass_within_5m, u.second_mode_share, u.multimodal};
}

io::FramePose frame_pose(const io::RouteFrame& f, const FrameEstimate& e, const osm::RegionProjection& projection) {
  io::FramePose pose;
  pose.uncertainty = e.uncertainty;
  pose.entropy = e.entropy;
  pose.etu_weight = e.etu_weight;
  pose.volume_power = e.volume_power;
  pose.relocalized = e.relocalized;
  double gamma = 0;
  const osm::GeoPoint geo = projection.reverse({e.x_m, e.y_m}, gamma);
  pose.frame = f.frame;
  pose.timestamp_s = f.timestamp_s;
  pose.x_m = e.x_m;
  pose.y_m = e.y_m;
  pose.lat_deg = geo.lat_deg;
  pose.lon_deg = geo.lon_deg;
  pose.compass_heading_deg = core::wrap360(e.grid_heading_deg + gamma);  // compass = grid + gamma
  pose.grid_heading_deg = core::wrap360(e.grid_heading_deg);
  if (f.truth) {
    double gamma_true = 0;
    const auto t = projection.forward(f.truth->where, gamma_true);
    const double ex = e.x_m - t.x_m, ey = e.y_m - t.y_m;
    pose.position_error_m = std::hypot(ex, ey);
    pose.truth =
        io::FramePose::Truth{t.x_m, t.y_m, f.truth->where.lat_deg, f.truth->where.lon_deg, std::nullopt, std::nullopt};
    if (f.truth->heading_deg) {
      pose.truth->grid_heading_deg = core::wrap360(*f.truth->heading_deg - gamma_true);
      pose.truth->compass_heading_deg = core::wrap360(*f.truth->heading_deg);
      pose.heading_error_deg = core::heading_difference_deg(pose.compass_heading_deg, *f.truth->heading_deg);
      const double h = *pose.truth->grid_heading_deg * core::kDegToRad;
      pose.longitudinal_error_m = ex * std::sin(h) + ey * std::cos(h);
      pose.lateral_error_m = -ex * std::cos(h) + ey * std::sin(h);
    }
  }
  return pose;
}

namespace {

// localize_route once the options and the route's crops are checked.
// `catalog` and `regions` (each frame's region) for a route over a catalog's regions (every mode
// follows a route that crosses from one into the next); null for a route in `cache` alone.
io::RouteResult run_route(const io::Route& route, raster::CacheReader& cache, const LocalizeOptions& options,
                          io::Mode mode, const std::function<void()>& on_frame, FrameSource source,
                          const FrameInspector& inspect, const RegionCatalog* catalog = nullptr,
                          const std::vector<std::size_t>* regions = nullptr) {
  if (!source) source = stored_route_frames(route, cache, options, frame_reads(mode, route));
  const auto estimator = make_mode(mode, {route, cache, options, inspect, catalog, regions});
  FramePrefetcher frames(std::move(source), route.frames.size(), estimator->lookahead());
  io::RouteResult result;
  result.route = route.name;
  result.mode = mode;
  if (mode == io::Mode::online || mode == io::Mode::seqloc) result.lag = options.lag;
  const auto& projection = cache.metadata().projection();
  const std::string name = cache.path().stem().string();
  for (std::size_t i = 0; i < route.frames.size(); ++i) {
    const std::size_t r = regions ? (*regions)[i] : 0;
    raster::CacheReader& region = catalog ? catalog->cache(r) : cache;
    const osm::RegionProjection& crs = catalog ? catalog->projection(r) : projection;
    const GridCrop crop = frame_crop(route.frames[i], region.grid(), crs);
    result.poses.push_back(frame_pose(route.frames[i], estimator->estimate(i, crop, frames), crs));
    result.poses.back().region = catalog ? catalog->name(r) : name;
    if (i > 0 && r != (regions ? (*regions)[i - 1] : 0)) ++result.region_crossings;
    if (on_frame) on_frame();
  }
  estimator->finish(result);
  result.prepare_seconds = frames.prepare_seconds();
  result.wait_seconds = frames.wait_seconds();
  return result;
}

}  // namespace

io::RouteResult localize_route(const io::Route& route, raster::CacheReader& cache, const LocalizeOptions& options,
                               io::Mode mode, const std::function<void()>& on_frame, FrameSource source,
                               const FrameInspector& inspect) {
  options.validate();
  check_crops(route, cache.grid(), cache.metadata().projection(), options);
  return run_route(route, cache, options, mode, on_frame, std::move(source), inspect);
}

namespace {

// A route stays in a region while its crops are half a belief window inside it.
double region_margin_m(const LocalizeOptions& options) {
  return std::max(options.filter.width, options.filter.height) * raster::kCellM / 2;
}

// The route's legs (runs of frames in one region) as routes of their own, for check_crops.
void check_legs(const io::Route& route, const RegionCatalog& catalog, const std::vector<std::size_t>& regions,
                const LocalizeOptions& options) {
  std::size_t begin = 0;
  for (std::size_t i = 1; i <= regions.size(); ++i) {
    if (i < regions.size() && regions[i] == regions[begin]) continue;
    const raster::RegionGrid& grid = catalog.cache(regions[begin]).grid();
    if (begin == 0 && i == regions.size()) {
      check_crops(route, grid, catalog.projection(regions[begin]), options);  // one leg: the route itself
    } else {
      io::Route leg;
      leg.dir = route.dir;
      leg.name = route.name;
      leg.frames.assign(route.frames.begin() + static_cast<std::ptrdiff_t>(begin),
                        route.frames.begin() + static_cast<std::ptrdiff_t>(i));
      check_crops(leg, grid, catalog.projection(regions[begin]), options);
    }
    begin = i;
  }
}

}  // namespace

void check_route(const io::Route& route, const RegionCatalog& catalog, const LocalizeOptions& options) {
  check_legs(route, catalog, route_regions(route, catalog, region_margin_m(options)), options);
}

BatchResult localize_routes(const std::vector<io::Route>& routes, raster::CacheReader& cache,
                            const LocalizeOptions& options, const std::vector<io::Mode>& modes,
                            const std::function<void()>& on_frame) {
  RegionCatalog catalog(cache);
  return localize_routes(routes, catalog, options, modes, on_frame);
}

BatchResult localize_routes(const std::vector<io::Route>& routes, const RegionCatalog& catalog,
                            const LocalizeOptions& options, const std::vector<io::Mode>& modes,
                            const std::function<void()>& on_frame) {
  options.validate();
  std::vector<std::vector<std::size_t>> regions;
  for (const auto& route : routes) {
    regions.push_back(route_regions(route, catalog, region_margin_m(options)));
    check_legs(route, catalog, regions.back(), options);
  }
  struct Job {
    std::size_t route;
    io::Mode mode;
  };
  std::vector<Job> jobs;
  for (std::size_t r = 0; r < routes.size(); ++r) {
    for (const auto mode : modes) jobs.push_back({r, mode});
  }
  const int threads = options.filter.threads;
  const int workers = std::max(1, std::min(threads, static_cast<int>(jobs.size())));
  LocalizeOptions job_options = options;
  if (workers > 1) job_options.filter.threads = std::max(1, threads / workers);
  job_options.matcher.threads = job_options.filter.threads;
  const std::size_t budget = options.frame_memory_mb * (std::size_t{1} << 20) / static_cast<std::size_t>(workers);

  // A route's store lives from its first job's start to its last job's end.
  struct Shared {
    std::shared_ptr<FrameStore> store;
    std::size_t jobs_left = 0;
  };
  std::vector<Shared> shared(routes.size());
  for (auto& s : shared) s.jobs_left = modes.size();

  BatchResult batch;
  batch.results.resize(jobs.size());
  std::mutex mutex;  // guards shared and batch's counters
  auto readers = [&](const io::Route& route) {
    int sum = 0;
    for (const auto mode : modes) sum += frame_reads(mode, route);
    return sum;
  };
  auto store_for = [&](std::size_t r) {
    std::lock_guard lock(mutex);
    if (!shared[r].store) {
      auto cache_of = [&catalog, &regions, r](std::size_t i) -> raster::CacheReader& {
        return catalog.cache(regions[r][i]);
      };
      shared[r].store =
          std::make_shared<FrameStore>(frames_from(routes[r], cache_of, job_options), routes[r].frames.size(),
                                       readers(routes[r]), budget, options.spill_dir);
    }
    return shared[r].store;
  };
  auto done_with = [&](std::size_t r) {
    std::lock_guard lock(mutex);
    if (--shared[r].jobs_left > 0) return;
    const auto stats = shared[r].store->stats();
    batch.frames_made += stats.made;
    batch.frames_spilled += stats.spilled;
    batch.peak_frame_memory_bytes = std::max(batch.peak_frame_memory_bytes, stats.peak_memory_bytes);
    shared[r].store.reset();
  };
  core::run_jobs(jobs.size(), workers, [&](std::size_t j) {
    const auto store = store_for(jobs[j].route);
    const std::size_t r = jobs[j].route;
    const io::Mode mode = jobs[j].mode;
    batch.results[j] = run_route(routes[r], catalog.cache(regions[r].front()), job_options, mode, on_frame,
                                 store->source(), {}, &catalog, &regions[r]);
    done_with(jobs[j].route);
  });
  return batch;
}

void perturb_odometry(io::Route& route, double translation_pct, double rotation_deg_per_m, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> normal(0.0, 1.0);
  for (std::size_t i = 1; i < route.frames.size(); ++i) {
    auto& o = route.frames[i].odometry;
    const double step = std::hypot(o.forward_m, o.left_m);
    const double sigma_t = translation_pct / 100.0 * step, sigma_r = rotation_deg_per_m * step;
    o.forward_m += sigma_t * normal(rng);
    o.left_m += sigma_t * normal(rng);
    o.yaw_deg += sigma_r * normal(rng);
  }
}

}  // namespace seqloc::pipeline
