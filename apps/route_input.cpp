#include "command.hpp"
#include "seqloc/io/route.hpp"
#include "seqloc/pipeline/localize.hpp"

namespace seqloc::app {

void add_route_limit_options(CLI::App& app, io::RouteLimits& limits) {
  app.add_option("--max-step", limits.max_step_m, "Largest plausible odometry step, m")->capture_default_str();
  app.add_option("--max-speed", limits.max_speed_mps, "Largest plausible speed, m/s")->capture_default_str();
  app.add_option("--max-yaw", limits.max_yaw_deg, "Largest plausible yaw per step, degrees")->capture_default_str();
}

std::vector<io::Route> read_checked_routes(const std::vector<std::filesystem::path>& dirs,
                                           const io::RouteLimits& limits, raster::CacheReader& cache,
                                           const pipeline::LocalizeOptions& options) {
  auto routes = io::read_routes(dirs, limits);
  for (const auto& route : routes) pipeline::check_crops(route, cache.grid(), cache.metadata().projection(), options);
  return routes;
}

}  // namespace seqloc::app
