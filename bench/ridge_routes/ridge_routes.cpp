// bench/ridge_routes: self-calibration on the ridge routes of the tests (tests/filter/ridge_routes.hpp),
// against the naive recursion, SeqLoc without self-calibration and the best fixed power per route:
// the defaults (the one-step criterion with the frames' shared errors), the one-step criterion
// alone (self_calibration_shared_lag 0), the bank and the sharpness slope
// (self_calibration_sharpness); and how honest the defaults' reported mass within 5 m is
// (pose_uncertainty's, binned by tenths against the share of frames truly within 5 m:
// io::uncertainty_calibration). Prints a table per kind of route and ends with one line of JSON.

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <string>
#include <vector>

#include "filter/ridge_routes.hpp"
#include "seqloc/io/results.hpp"
#include "seqloc/uncertainty/pose_uncertainty.hpp"

namespace {

using seqloc::filter::FilterConfig;
using seqloc::filter::test::ridge_recall;
using seqloc::filter::test::RidgeKind;
using seqloc::filter::test::RidgeRoute;

struct Row {
  double naive = 0, off = 0, defaults = 0, one_step = 0, bank = 0, sharpness = 0, best_fixed = 0;
};

// Each step's pose with its uncertainty and the truth, in window metres (east, north), as
// io::uncertainty_calibration takes them.
seqloc::filter::test::RidgeStepReader keep_poses(std::vector<seqloc::io::FramePose>& poses) {
  return [&poses](const seqloc::filter::SeqLocFilter& filter, const seqloc::filter::FrameResult& r,
                  const RidgeRoute::Frame& f) {
    const auto u = seqloc::uncertainty::pose_uncertainty(filter.belief(), r.pose);
    seqloc::io::FramePose p;
    p.x_m = r.pose.u * 0.5;
    p.y_m = -r.pose.v * 0.5;
    p.truth.emplace();
    p.truth->x_m = f.truth_u * 0.5;
    p.truth->y_m = -f.truth_v * 0.5;
    p.uncertainty.emplace();
    p.uncertainty->cov_xx_m2 = u.cov_ee_m2;
    p.uncertainty->cov_xy_m2 = u.cov_en_m2;
    p.uncertainty->cov_yy_m2 = u.cov_nn_m2;
    p.uncertainty->mass_within_5m = u.mass_within_5m;
    poses.push_back(p);
  };
}

Row measure(const RidgeKind& kind, int routes, int frames, unsigned first_seed,
            std::vector<seqloc::io::FramePose>& poses) {
  FilterConfig naive = RidgeRoute::config();
  naive.etu = naive.mgr = naive.pas = naive.self_calibrate = false;
  FilterConfig off = RidgeRoute::config();
  off.self_calibrate = false;
  const FilterConfig defaults = RidgeRoute::config();
  FilterConfig one_step = RidgeRoute::config();
  one_step.self_calibration_shared_lag = 0;
  FilterConfig bank = RidgeRoute::config();
  bank.self_calibration_bank = true;
  FilterConfig sharpness = RidgeRoute::config();
  sharpness.self_calibration_sharpness = true;
  Row mean;
  for (int r = 0; r < routes; ++r) {
    const auto seed = first_seed + static_cast<unsigned>(r);
    const auto best = seqloc::filter::test::best_fixed_power(kind, seed, off, frames);
    const Row row{ridge_recall(kind, seed, naive, frames),
                  ridge_recall(kind, seed, off, frames),
                  ridge_recall(kind, seed, defaults, frames, 1, 5, keep_poses(poses)),
                  ridge_recall(kind, seed, one_step, frames),
                  ridge_recall(kind, seed, bank, frames),
                  ridge_recall(kind, seed, sharpness, frames),
                  best.recall};
    std::printf(
        "  route %d: naive %5.1f  no self-cal %5.1f  defaults %5.1f  one-step alone %5.1f  bank %5.1f  sharpness "
        "%5.1f  best fixed %5.1f (power %.3g)\n",
        r, row.naive, row.off, row.defaults, row.one_step, row.bank, row.sharpness, row.best_fixed, best.power);
    mean.naive += row.naive / routes;
    mean.off += row.off / routes;
    mean.defaults += row.defaults / routes;
    mean.one_step += row.one_step / routes;
    mean.bank += row.bank / routes;
    mean.sharpness += row.sharpness / routes;
    mean.best_fixed += row.best_fixed / routes;
  }
  return mean;
}

// Prints the defaults' reliability table (bins of the reported mass within 5 m) and returns its
// JSON fields: the ECE and the largest |reported - actual| over bins of at least 50 frames.
std::string reliability(const seqloc::io::UncertaintyCalibration& c) {
  std::printf("  the defaults' reported mass within 5 m (coverage of the 95 %% ellipse %.1f %%, ECE %.1f points):\n",
              c.coverage_95_pct, c.mass_5m_ece_pts);
  double worst = 0;
  for (std::size_t b = 0; b < c.reliability.size(); ++b) {
    const auto& bin = c.reliability[b];
    if (bin.frames == 0) continue;
    std::printf("    %3zu-%3zu %%: %4zu frames, reported %5.1f %%, truly within 5 m %5.1f %%\n", 10 * b, 10 * b + 10,
                bin.frames, bin.reported_pct, bin.actual_pct);
    if (bin.frames >= 50) worst = std::max(worst, std::abs(bin.reported_pct - bin.actual_pct));
  }
  char buffer[160];
  std::snprintf(buffer, sizeof buffer,
                ", \"defaults_coverage_95_pct\": %.1f, \"defaults_mass_5m_ece_pts\": %.1f, "
                "\"defaults_worst_bin_of_50_pts\": %.1f}",
                c.coverage_95_pct, c.mass_5m_ece_pts, worst);
  return buffer;
}

}  // namespace

int main(int argc, char** argv) {
  int routes = 6, frames = 60;
  unsigned first_seed = 1000;  // seeds the tests do not use
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    if (flag == "--routes") {
      routes = std::atoi(argv[i + 1]);
    } else if (flag == "--frames") {
      frames = std::atoi(argv[i + 1]);
    } else if (flag == "--seed") {
      first_seed = static_cast<unsigned>(std::strtoul(argv[i + 1], nullptr, 10));
    } else {
      std::fprintf(stderr, "usage: bench_ridge_routes [--routes N] [--frames N] [--seed FIRST]\n");
      return 2;
    }
  }
  if (routes < 1 || frames < 1) {
    std::fprintf(stderr, "bench_ridge_routes: --routes and --frames must be at least 1\n");
    return 2;
  }
  const std::vector<std::pair<std::string, RidgeKind>> kinds{
      {"sharp_shared", seqloc::filter::test::sharp_shared()},
      {"timid", seqloc::filter::test::timid()},
      {"distinctive_wrong", seqloc::filter::test::distinctive_wrong()}};
  std::string json = "{\"bench\": \"ridge_routes\", \"routes\": " + std::to_string(routes) +
                     ", \"frames\": " + std::to_string(frames) + ", \"first_seed\": " + std::to_string(first_seed);
  for (const auto& [name, kind] : kinds) {
    std::printf("%s (R@5m, %d routes x %d frames, seeds from %u):\n", name.c_str(), routes, frames, first_seed);
    std::vector<seqloc::io::FramePose> poses;
    const Row m = measure(kind, routes, frames, first_seed, poses);
    std::printf(
        "  mean:    naive %5.1f  no self-cal %5.1f  defaults %5.1f  one-step alone %5.1f  bank %5.1f  sharpness "
        "%5.1f  best fixed %5.1f\n",
        m.naive, m.off, m.defaults, m.one_step, m.bank, m.sharpness, m.best_fixed);
    char buffer[320];
    std::snprintf(buffer, sizeof buffer,
                  ", \"%s\": {\"naive\": %.1f, \"no_self_calibration\": %.1f, \"defaults\": %.1f, "
                  "\"one_step_alone\": %.1f, \"bank\": %.1f, \"sharpness\": %.1f, \"best_fixed\": %.1f",
                  name.c_str(), m.naive, m.off, m.defaults, m.one_step, m.bank, m.sharpness, m.best_fixed);
    json += buffer;
    json += reliability(*seqloc::io::uncertainty_calibration(poses));
  }
  std::printf("%s}\n", json.c_str());
  return 0;
}
