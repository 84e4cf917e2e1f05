#include "seqloc/pipeline/localize_run.hpp"

#include <algorithm>
#include <atomic>
#include <mutex>

#include "seqloc/pipeline/backbone_calibration.hpp"
#include "seqloc/pipeline/region_catalog.hpp"
#include "seqloc/ros/route_bag.hpp"

namespace seqloc::pipeline {
namespace {

// One line for the log, when anyone listens.
template <class... Parts>
void note(const LocalizeRunEvents& events, const Parts&... parts) {
  if (!events.note) return;
  std::string line;
  (line.append(parts), ...);
  events.note(line);
}

// Bags come from the modes with a belief (their poses carry an uncertainty): asking for bags of
// single or offline alone is a mistake said before any work.
void check_bags(const ros::BagOptions& bags, const std::vector<io::Mode>& modes) {
  bags.validate();
  const bool any = std::any_of(modes.begin(), modes.end(),
                               [](io::Mode m) { return m != io::Mode::single && m != io::Mode::offline; });
  if (!any) {
    throw UsageError(
        "ROS 2 bags come from the modes with a belief (online, seqloc, smooth); single and offline "
        "poses carry no uncertainty");
  }
}

}  // namespace

LocalizeRunReport run_localize(LocalizeRun run, const LocalizeRunEvents& events) {
  if (!run.calibration.empty()) apply_calibration_file(run.calibration, run.options);
  check_device(run.options.device, run.options.filter);  // before any work: one line if it cannot run here
  if (run.bags) check_bags(*run.bags, run.modes);
  const RegionCatalog catalog(run.regions, 256);
  if (catalog.size() > 1) note(events, std::to_string(catalog.size()), " regions");
  auto routes = io::read_routes(run.routes, run.limits, run.shard,
                                [&](const io::Route& other) { check_route(other, catalog, run.options); });
  if (run.noise.any()) {
    for (auto& route : routes) {
      perturb_odometry(route, run.noise.translation_pct, run.noise.rotation_deg_per_m, run.noise.seed);
    }
  }
  LocalizeRunReport report;
  report.routes = routes.size();
  report.regions = catalog.size();
  report.frames = static_cast<long long>(io::frame_count(routes));
  const long long total = report.frames * static_cast<long long>(run.modes.size());  // frames times modes
  if (run.shard.count > 1) {
    note(events, "shard ", std::to_string(run.shard.index), "/", std::to_string(run.shard.count), ": ",
         std::to_string(routes.size()), " of ", std::to_string(run.routes.size()), " routes");
  }
  note(events, "localize ", std::to_string(routes.size()), " routes, ", std::to_string(total), " frames in all");

  io::RunFolderWriter out(run.output);  // staged beside the output, in place only when complete
  std::atomic<long long> done{0};
  std::mutex progress;
  const auto batch = localize_routes(routes, catalog, run.options, run.modes, [&] {
    const long long d = ++done;
    if (!events.frames) return;
    std::lock_guard lock(progress);
    events.frames(d, total);
  });
  report.frames_made = batch.frames_made;
  report.frames_spilled = batch.frames_spilled;
  report.peak_frame_memory_bytes = batch.peak_frame_memory_bytes;
  for (const auto& result : batch.results) {
    const std::filesystem::path dir = out.add(result);
    if (run.bags && ros::has_uncertainty(result)) {
      ros::write_route_bag(dir / "bag", result, *run.bags);
      ++report.bags;
    }
  }
  std::vector<std::string> names;
  names.reserve(routes.size());
  for (const auto& route : routes) names.push_back(route.name);
  report.metrics = out.commit(names);
  return report;
}

}  // namespace seqloc::pipeline
