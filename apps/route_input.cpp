#include <algorithm>
#include <set>
#include <string>

#include "command.hpp"
#include "seqloc/pipeline/localize.hpp"

namespace seqloc::app {

std::vector<pipeline::Route> read_checked_routes(std::vector<std::filesystem::path> dirs, raster::CacheReader& cache,
                                                 const pipeline::LocalizeOptions& options) {
  std::sort(dirs.begin(), dirs.end());
  std::vector<pipeline::Route> routes;
  std::set<std::string> names;
  for (std::size_t k = 0; k < dirs.size(); ++k) {
    auto route = pipeline::read_route(dirs[k]);
    // Two folders of one name (from different parents) keep apart in the output.
    if (!names.insert(route.name).second) route.name += "-" + std::to_string(k + 1);
    names.insert(route.name);
    pipeline::check_crops(route, cache.grid(), cache.metadata().projection(), options);
    routes.push_back(std::move(route));
  }
  return routes;
}

std::size_t frame_count(const std::vector<pipeline::Route>& routes) {
  std::size_t n = 0;
  for (const auto& r : routes) n += r.frames.size();
  return n;
}

}  // namespace seqloc::app
