// bench/paper_tables: the analogues of the seed paper's tables on real OSM regions, from simulated
// routes scored by the built-in matcher. Each route's volumes are computed once and shared by
// every configuration; configurations run side by side. Writes report.md,
// entropy_scatter_<region>.png and results.json under the output folder and ends with one line of
// JSON.
//   bench_paper_tables --work DIR --out DIR [--window 160] [--threads 2] [--tables overall,tempered,...]
// --tables runs only those tables' configurations (overall, ablation, eps, pas, noise, tempered,
// smoothing, extras; the overall table's are always run, as the others compare with them).
// DIR/<region>.gpkg and DIR/<region>-routes/route_* must exist (bench/paper_tables/run makes them).

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <filesystem>
#include <fstream>
#include <map>
#include <sstream>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "seqloc/core/thread_pool.hpp"
#include "seqloc/io/run_folder.hpp"
#include "seqloc/pipeline/localize.hpp"
#include "seqloc/pipeline/volume_shape.hpp"
#include "seqloc/render/render.hpp"

namespace io = seqloc::io;
namespace core = seqloc::core;
namespace matcher = seqloc::matcher;
namespace render = seqloc::render;
namespace filter = seqloc::filter;
namespace pipeline = seqloc::pipeline;
namespace raster = seqloc::raster;
namespace fs = std::filesystem;
using Clock = std::chrono::steady_clock;

namespace {

struct Config {
  std::string table, name;
  io::Mode mode = io::Mode::seqloc;
  std::function<void(filter::FilterConfig&)> tweak;
  double noise_t = 0, noise_r = 0;  // odometry noise (% of step, deg per m)
  double sharpen = 1;               // the volumes raised to this power k (k log p: k > 1 overconfident)
  int offline_half_window = 10;     // offline: frames within +-K (all when < 0)
  int lag = 0;                      // seqloc: fixed-lag smoothing over this many later frames
};

// Fixed lags of the smoothing table (0 is SeqLoc itself, which the table shows as such).
constexpr int kLags[] = {5, 10, 20};

// The paper's exact configuration (filter::paper_config: ETU w = 1 - H, unobserved cells at
// log(1/M), no self-calibration) in the bench's window and threads.
void paper(filter::FilterConfig& f) {
  filter::FilterConfig p = filter::paper_config();
  p.width = f.width;
  p.height = f.height;
  p.threads = f.threads;
  f = p;
}

void no_self_calibration(filter::FilterConfig& f) { f.self_calibrate = false; }

// Backbones out of calibration: the matcher's volumes tempered by k (k log p, renormalized).
constexpr double kTempering[] = {0.25, 0.5, 2, 4, 8};
constexpr double kSharpen = 4;  // the overconfident backbone of the paper's configuration's row

std::string tempered_name(const char* what, double k) {
  char n[96];
  std::snprintf(n, sizeof n, "%s, k = %g", what, k);
  return n;
}

std::vector<Config> configs() {
  using M = io::Mode;
  auto none = [](filter::FilterConfig&) {};
  std::vector<Config> c;
  c.push_back({"overall", "single frame", M::single, none});
  c.push_back({"overall", "offline (+-10 frames)", M::offline, none});
  // conventions.md section 6's offline: every frame of the route (the product's default is +-10,
  // which bounds memory and time on long routes).
  c.push_back({"overall", "offline (all frames)", M::offline, none, 0, 0, 1, -1});
  c.push_back({"overall", "online (naive recursion)", M::online, none});
  c.push_back({"overall", "SeqLoc", M::seqloc, none});
  c.push_back({"overall", "SeqLoc, paper's configuration", M::seqloc, paper});
  c.push_back({"ablation", "+MGR", M::seqloc, [](auto& f) { f.etu = f.pas = false; }});
  c.push_back({"ablation", "+MGR+ETU", M::seqloc, [](auto& f) { f.pas = false; }});
  for (double eps : {0.02, 0.03, 0.04, 0.05}) {
    char n[32];
    std::snprintf(n, sizeof n, "eps = %.2f", eps);
    c.push_back({"eps", n, M::seqloc, [eps](auto& f) { f.mgr_epsilon = eps; }});
  }
  for (int r : {1, 5, 10}) c.push_back({"pas", "r = " + std::to_string(r), M::seqloc, [r](auto& f) { f.pas_radius = r; }});
  const struct { const char* name; double t, r; } noise[] = {
      {"good (1%, 0.005 deg/m)", 1, 0.005}, {"medium (2%, 0.010 deg/m)", 2, 0.010},
      {"poor (5%, 0.020 deg/m)", 5, 0.020}, {"very poor (10%, 0.050 deg/m)", 10, 0.050}};
  for (const auto& n : noise) c.push_back({"noise", n.name, M::seqloc, none, n.t, n.r});
  // Volumes out of calibration, as a network trained elsewhere gives them: each k with
  // self-calibration on (SeqLoc) and off; k = 1 is the overall table's SeqLoc.
  c.push_back({"tempered", tempered_name("SeqLoc without self-calibration", 1), M::seqloc, no_self_calibration});
  for (const double k : kTempering) {
    c.push_back({"tempered", tempered_name("SeqLoc", k), M::seqloc, none, 0, 0, k});
    c.push_back({"tempered", tempered_name("SeqLoc without self-calibration", k), M::seqloc, no_self_calibration, 0, 0, k});
  }
  // The batch modes on the same volumes (k = 1: the smoothing table's smooth and lag 10).
  for (const double k : kTempering) {
    c.push_back({"tempered", tempered_name("smooth", k), M::smooth, none, 0, 0, k});
    c.push_back({"tempered", tempered_name("SeqLoc, lag 10", k), M::seqloc, none, 0, 0, k, 10, 10});
  }
  c.push_back({"tempered", tempered_name("online (naive recursion)", kSharpen), M::online, none, 0, 0, kSharpen});
  c.push_back({"tempered", tempered_name("SeqLoc, paper's configuration", kSharpen), M::seqloc, paper, 0, 0, kSharpen});
  // Batch routes: the whole route's evidence (smooth), and real time with a delay of L frames.
  c.push_back({"smoothing", "smooth (every frame given the whole route)", M::smooth, none});
  for (const int lag : kLags) {
    c.push_back({"smoothing", "SeqLoc, lag " + std::to_string(lag), M::seqloc, none, 0, 0, 1, 10, lag});
  }
  c.push_back({"extras", "+sub-bin heading", M::seqloc, [](auto& f) { f.subbin_heading = true; }});
  c.push_back({"extras", "+motion noise", M::seqloc, [](auto& f) { f.motion_noise = true; }});
  c.push_back({"extras", "+GPS term (first frame's fix)", M::seqloc, [](auto& f) { f.gps_prior = true; }});
  return c;
}

std::string row(const std::string& name, const io::Metrics& m) {
  char b[512];
  std::snprintf(b, sizeof b, "| %s | %zu | %.1f | %.1f | %.1f | %.1f | %.1f | %.1f | %.2f | %.2f |\n", name.c_str(), m.frames,
                m.position_recall[0], m.position_recall[1], m.position_recall[2], m.heading_recall[0], m.heading_recall[1],
                m.heading_recall[2], m.mean_position_error_m, m.mean_heading_error_deg);
  return b;
}
const char* kHeader =
    "| configuration | frames | R@1m | R@3m | R@5m | R@1° | R@3° | R@5° | mean m | mean ° |\n"
    "|---|---:|---:|---:|---:|---:|---:|---:|---:|---:|\n";

// Spearman's rank correlation of (x, y) pairs (tied values get their mean rank).
double spearman(const std::vector<std::pair<double, double>>& points) {
  const std::size_t n = points.size();
  auto ranks = [n](const std::vector<double>& x) {
    std::vector<std::size_t> order(n);
    for (std::size_t i = 0; i < n; ++i) order[i] = i;
    std::sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return x[a] < x[b]; });
    std::vector<double> r(n);
    for (std::size_t i = 0; i < n;) {
      std::size_t j = i;
      while (j + 1 < n && x[order[j + 1]] == x[order[i]]) ++j;
      for (std::size_t k = i; k <= j; ++k) r[order[k]] = (static_cast<double>(i + j) / 2.0) + 1.0;
      i = j + 1;
    }
    return r;
  };
  std::vector<double> xs, ys;
  for (const auto& [x, y] : points) {
    xs.push_back(x);
    ys.push_back(y);
  }
  const auto rx = ranks(xs), ry = ranks(ys);
  const double mean = (static_cast<double>(n) + 1) / 2;
  double sxy = 0, sxx = 0, syy = 0;
  for (std::size_t i = 0; i < n; ++i) {
    sxy += (rx[i] - mean) * (ry[i] - mean);
    sxx += (rx[i] - mean) * (rx[i] - mean);
    syy += (ry[i] - mean) * (ry[i] - mean);
  }
  return sxx > 0 && syy > 0 ? sxy / std::sqrt(sxx * syy) : 0.0;
}

using PosesByConfig = std::map<std::string, std::map<std::string, std::vector<io::FramePose>>>;

// 9. How honest the poses' uncertainty is (io::uncertainty_calibration): for the configurations
// that report one, per group, the share of frames whose truth lies inside the reported 95 %
// ellipse and the mass-within-5-m ECE; then the reliability of SeqLoc's and smooth's mass within
// 5 m, with a picture. Appends to `md` and `results`.
void honesty_section(const PosesByConfig& poses, const std::vector<std::string>& configs, const fs::path& out,
                     std::ostringstream& md, nlohmann::ordered_json& results) {
  md << "\n## 9. The uncertainty's honesty (docs/route-format.md, \"Uncertainty\")\n\n"
     << "Coverage: % of frames whose truth lies inside the reported 95 % position ellipse (target 95). ECE: the "
        "reported mass within 5 m, binned by tenths, against the share of frames truly within 5 m, |difference| "
        "averaged over frames (points; target <= 5).\n\n"
     << "| configuration | group | frames | coverage of the 95 % ellipse | mass-within-5-m ECE (points) |\n"
     << "|---|---|---:|---:|---:|\n";
  std::vector<render::Series> curves;
  for (const auto& name : configs) {
    const auto found = poses.find(name);
    if (found == poses.end()) continue;
    for (const std::string group : {"feature-sparse", "urban"}) {
      const auto g = found->second.find(group);
      if (g == found->second.end()) continue;
      const auto c = io::uncertainty_calibration(g->second);
      if (!c) continue;
      char b[320];
      std::snprintf(b, sizeof b, "| %s | %s | %zu | %.1f | %.1f |\n", name.c_str(), group.c_str(), c->frames,
                    c->coverage_95_pct, c->mass_5m_ece_pts);
      md << b;
      results["uncertainty"][group][name] = {
          {"frames", c->frames}, {"coverage_95_pct", c->coverage_95_pct}, {"mass_5m_ece_pts", c->mass_5m_ece_pts}};
    }
  }
  // The reliability of SeqLoc's and smooth's mass within 5 m, both groups pooled (a curve per
  // group and configuration leaves too few frames in the middle bins to read).
  md << "\n| configuration (both groups) | reported mass within 5 m | frames | mean reported % | truly within 5 m % |\n"
     << "|---|---|---:|---:|---:|\n";
  for (const std::string name : {"SeqLoc", "smooth (every frame given the whole route)"}) {
    const auto found = poses.find(name);
    if (found == poses.end()) continue;
    std::vector<io::FramePose> pooled;
    for (const std::string group : {"feature-sparse", "urban"}) {
      const auto g = found->second.find(group);
      if (g != found->second.end()) pooled.insert(pooled.end(), g->second.begin(), g->second.end());
    }
    const auto c = io::uncertainty_calibration(pooled);
    if (!c) continue;
    // Short legend names; only bins of at least 20 frames are drawn (the table has them all).
    render::Series series{name.starts_with("smooth") ? "smooth" : name, {}, {}, false};
    for (std::size_t b = 0; b < c->reliability.size(); ++b) {
      const auto& bin = c->reliability[b];
      if (bin.frames == 0) continue;
      char line[256];
      std::snprintf(line, sizeof line, "| %s | %zu-%zu %% | %zu | %.1f | %.1f |\n", name.c_str(), 10 * b, 10 * b + 10,
                    bin.frames, bin.reported_pct, bin.actual_pct);
      md << line;
      if (bin.frames < 20) continue;
      series.x.push_back(bin.reported_pct);
      series.y.push_back(bin.actual_pct);
    }
    series.points = series.x.size() < 2;  // a single bin is a dot, not a line
    curves.push_back(series);
  }
  if (curves.empty()) return;
  curves.push_back({"calibrated", {0, 100}, {0, 100}, false});
  render::write_picture(out / "reliability_mass_5m.png",
                        render::plot(curves, "Reported mass within 5 m against the share truly within 5 m",
                                     "reported mass within 5 m (%, bin mean; bins of 20 frames or more)",
                                     "frames truly within 5 m (%)", 100));
  md << "\n![reliability](reliability_mass_5m.png)\n";
}

}  // namespace

int main(int argc, char** argv) {
  fs::path work, out;
  int window = 160, threads = 2;
  std::string only;  // ",table,table," or empty for all
  double temperature = matcher::MatcherConfig{}.temperature;
  double miss_rate = matcher::MatcherConfig{}.miss_rate;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string a = argv[i];
    if (a == "--work") work = argv[i + 1];
    else if (a == "--out") out = argv[i + 1];
    else if (a == "--window") window = std::stoi(argv[i + 1]);
    else if (a == "--threads") threads = std::stoi(argv[i + 1]);
    else if (a == "--temperature") temperature = std::stod(argv[i + 1]);
    else if (a == "--miss-rate") miss_rate = std::stod(argv[i + 1]);
    else if (a == "--tables") only = "," + std::string(argv[i + 1]) + ",";
  }
  if (work.empty() || out.empty()) {
    std::fprintf(stderr, "usage: bench_paper_tables --work DIR --out DIR [--window 160] [--threads 2]\n");
    return 2;
  }
  fs::create_directories(out);
  const std::vector<std::pair<std::string, std::string>> regions = {
      {"andorra", "feature-sparse"}, {"north-bayreuth", "feature-sparse"}, {"monaco", "urban"}};
  std::vector<Config> all;
  for (auto& c : configs()) {
    if (only.empty() || c.table == "overall" || only.find("," + c.table + ",") != std::string::npos) all.push_back(c);
  }
  // poses[config][group] and per region for the entropy analysis.
  PosesByConfig poses;
  std::map<std::string, std::vector<io::FramePose>> single_by_region;
  std::map<std::string, std::map<std::string, std::vector<double>>> last_power;  // [config][group or region]
  std::map<std::string, std::vector<pipeline::VolumeShape>> shapes;
  const auto start = Clock::now();
  double matcher_seconds = 0;
  std::size_t frames_matched = 0, routes_per_region = 0;

  for (const auto& [region, group] : regions) {
    raster::CacheReader cache(work / (region + ".gpkg"), 512);
    std::vector<fs::path> dirs;
    for (const auto& e : fs::directory_iterator(work / (region + "-routes"))) {
      if (e.is_directory()) dirs.push_back(e.path());
    }
    std::sort(dirs.begin(), dirs.end());
    routes_per_region = dirs.size();
    for (const auto& dir : dirs) {
      const io::Route route = io::read_route(dir);
      pipeline::LocalizeOptions options;
      options.filter.width = options.filter.height = window;
      options.filter.threads = threads;
      options.matcher.threads = threads;
      options.matcher.temperature = temperature;
      options.matcher.miss_rate = miss_rate;
      // The route's volumes, once.
      const auto t0 = Clock::now();
      // The float16 values `seqloc localize` gives.
      const auto source = pipeline::stored_route_frames(route, cache, options);
      std::vector<std::shared_ptr<const filter::PreparedFrame>> frames(route.frames.size());
      for (std::size_t i = 0; i < frames.size(); ++i) frames[i] = source(i);
      matcher_seconds += std::chrono::duration<double>(Clock::now() - t0).count();
      frames_matched += frames.size();
      const pipeline::FrameSource shared = [&frames](std::size_t i) { return frames[i]; };
      const auto tempered = [&frames](double k) -> pipeline::FrameSource {
        return [&frames, k](std::size_t i) {
          return std::make_shared<const filter::PreparedFrame>(filter::temper_frame(*frames[i], k));
        };
      };
      // The likelihood's shape around the vehicle's heading (crops are region-grid north-up).
      const auto projection = cache.metadata().projection();
      for (std::size_t i = 0; i < frames.size(); ++i) {
        const auto& truth = route.frames[i].truth;
        if (!truth || !truth->heading_deg) continue;
        double gamma = 0;
        (void)projection.forward(truth->where, gamma);
        shapes[region].push_back(pipeline::volume_shape(*frames[i], *truth->heading_deg - gamma));
      }
      // Every configuration, side by side, one filter thread each.
      std::vector<io::RouteResult> results(all.size());
      core::run_jobs(all.size(), threads, [&](std::size_t c) {
        pipeline::LocalizeOptions o = options;
        o.filter.threads = 1;
        o.offline_half_window = all[c].offline_half_window;
        o.lag = all[c].lag;
        all[c].tweak(o.filter);
        io::Route r = route;
        // The noise's seed follows the configuration's name (FNV-1a), so that adding or leaving out
        // configurations does not redraw it.
        std::uint64_t seed = 1469598103934665603ull;
        for (const char ch : all[c].name) seed = (seed ^ static_cast<unsigned char>(ch)) * 1099511628211ull;
        if (all[c].noise_t > 0) pipeline::perturb_odometry(r, all[c].noise_t, all[c].noise_r, seed);
        results[c] = pipeline::localize_route(r, cache, o, all[c].mode, {},
                                              all[c].sharpen != 1 ? tempered(all[c].sharpen) : shared);
      });
      for (std::size_t c = 0; c < all.size(); ++c) {
        // Self-calibration's estimate after the route: the power its last frame was given.
        if (!results[c].poses.empty()) {
          last_power[all[c].name][group].push_back(results[c].poses.back().volume_power);
          last_power[all[c].name][region].push_back(results[c].poses.back().volume_power);
        }
        auto& g = poses[all[c].name][group];
        g.insert(g.end(), results[c].poses.begin(), results[c].poses.end());
        auto& reg = poses[all[c].name][region];
        reg.insert(reg.end(), results[c].poses.begin(), results[c].poses.end());
      }
      auto& s = single_by_region[region];
      s.insert(s.end(), results[0].poses.begin(), results[0].poses.end());
      std::fprintf(stderr, "%s %s: %zu frames, %.0f s elapsed\n", region.c_str(), route.name.c_str(), route.frames.size(),
                   std::chrono::duration<double>(Clock::now() - start).count());
    }
  }

  auto metrics = [&](const std::string& config, const std::string& group) {
    return io::compute_metrics(poses[config][group]);
  };
  std::ostringstream md;
  nlohmann::ordered_json results;
  md << "# SeqLoc on simulated routes over real OSM regions\n\n"
     << "Generated by `scripts/bench paper_tables` (bench/paper_tables). Feature-sparse: andorra + north-bayreuth; "
        "urban: monaco. Belief window "
     << window << " x " << window << " cells x 256 headings; volumes 128 x 128 x 256 from the built-in matcher "
     << "(temperature " << temperature << ", miss rate " << miss_rate << ").\n";
  const std::vector<std::pair<std::string, std::string>> tables = {
      {"overall", "1. Overall"}, {"ablation", "2. Ablation (naive recursion = online; +MGR+ETU+PAS = SeqLoc)"},
      {"eps", "3a. MGR eps (SeqLoc uses 0.01)"}, {"pas", "3b. PAS radius (SeqLoc uses 3)"},
      {"noise", "4. Odometry noise (none = SeqLoc)"},
      {"tempered", "5. Backbones out of calibration: the same volumes tempered by k (k log p, renormalized; k > 1 "
                   "overconfident, k < 1 timid; single frames keep their argmax); k = 1 is SeqLoc above"},
      {"smoothing", "5c. Batch routes: smooth and fixed lag (lag 0 is SeqLoc; offline over all frames is the product "
                    "smooth computes in linear time, without MGR's and ETU's robustness)"},
      {"extras", "6. Beyond the paper"}};
  for (const std::string group : {"feature-sparse", "urban"}) {
    md << "\n## " << group << "\n";
    for (const auto& entry : tables) {
      const std::string& table = entry.first;  // a name, not a binding: lambdas capture it
      const std::string& title = entry.second;
      if (std::none_of(all.begin(), all.end(), [&](const Config& c) { return c.table == table; })) continue;
      md << "\n### " << title << "\n\n" << kHeader;
      if (table == "ablation") md << row("naive recursion", metrics("online (naive recursion)", group));
      if (table == "eps" || table == "pas" || table == "noise" || table == "extras") md << row("SeqLoc", metrics("SeqLoc", group));
      if (table == "tempered") md << row("single frame", metrics("single frame", group));
      if (table == "smoothing") {
        md << row("offline (all frames)", metrics("offline (all frames)", group));
        md << row("SeqLoc (lag 0)", metrics("SeqLoc", group));
      }
      for (const auto& c : all) {
        if (c.table == table) md << row(c.name, metrics(c.name, group));
      }
      if (table == "ablation") md << row("+MGR+ETU+PAS (SeqLoc)", metrics("SeqLoc", group));
    }
  }
  // Every configuration's metrics in every column (the groups, then the regions): the source
  // docs/paper-tables.md's tables are written from (bench/paper_tables/write_doc.py).
  for (const auto& c : all) {
    for (const std::string column : {"feature-sparse", "urban", "andorra", "north-bayreuth", "monaco"}) {
      const auto m = metrics(c.name, column);
      results["metrics"][column][c.name] = {
          {"table", c.table},
          {"frames", m.frames},
          {"position_recall", {m.position_recall[0], m.position_recall[1], m.position_recall[2]}},
          {"heading_recall", {m.heading_recall[0], m.heading_recall[1], m.heading_recall[2]}},
          {"mean_position_error_m", m.mean_position_error_m},
          {"mean_heading_error_deg", m.mean_heading_error_deg}};
    }
  }
  md << "\n## Per region (overall, tempered, smoothing)\n\n" << kHeader;
  for (const auto& [region, group] : regions) {
    for (const auto& c : all) {
      if (c.table == "overall" || c.table == "tempered" || c.table == "smoothing") {
        md << row(region + ": " + c.name, metrics(c.name, region));
      }
    }
  }

  // 5b. What self-calibration estimated: the power of each route's last frame against 1 / k.
  auto median = [](std::vector<double> x) {
    if (x.empty()) return 0.0;
    std::nth_element(x.begin(), x.begin() + static_cast<std::ptrdiff_t>(x.size() / 2), x.end());
    return x[x.size() / 2];
  };
  const bool tempered_ran = std::any_of(all.begin(), all.end(), [](const Config& c) { return c.table == "tempered"; });
  if (tempered_ran) {
    md << "\n## 5b. Self-calibration's estimate (median over routes of the power given to the last frame)\n\n"
       << "| k | 1 / k |";
    std::vector<std::string> columns = {"feature-sparse", "urban"};
    for (const auto& [region, group] : regions) columns.push_back(region);
    for (const auto& col : columns) md << " " << col << " |";
    md << "\n|---:|---:|";
    for (std::size_t i = 0; i < columns.size(); ++i) md << "---:|";
    md << "\n";
    std::vector<double> ks = {1};
    ks.insert(ks.end(), std::begin(kTempering), std::end(kTempering));
    std::sort(ks.begin(), ks.end());
    for (const double k : ks) {
      const std::string name = k == 1 ? "SeqLoc" : tempered_name("SeqLoc", k);
      char b[64];
      std::snprintf(b, sizeof b, "| %g | %.3f |", k, 1 / k);
      md << b;
      for (const auto& col : columns) {
        std::snprintf(b, sizeof b, " %.3f |", median(last_power[name][col]));
        md << b;
        results["self_calibration"][col][std::to_string(k)] = median(last_power[name][col]);
      }
      md << "\n";
    }
  }

  // 7. Does entropy predict error? Single frames per region: recall per entropy tercile and the
  // rank correlation of entropy with error (the paper's supplementary scatter).
  md << "\n## 7. Entropy against error (single frames)\n\n"
     << "| region | frames | median entropy | R@5m, flattest third | R@5m, middle third | R@5m, sharpest third | "
        "Spearman(entropy, error) |\n|---|---:|---:|---:|---:|---:|---:|\n";
  std::ostringstream pictures;
  for (const auto& [region, group] : regions) {
    std::vector<std::pair<double, double>> points;  // (entropy, error)
    for (const auto& p : single_by_region[region]) {
      if (p.position_error_m) points.emplace_back(p.entropy, *p.position_error_m);
    }
    if (points.size() < 3) continue;
    std::sort(points.begin(), points.end());
    const std::size_t n = points.size();
    auto recall = [&](std::size_t b, std::size_t e) {
      std::size_t hit = 0;
      for (std::size_t i = b; i < e; ++i) hit += points[i].second < 5;
      return 100.0 * static_cast<double>(hit) / static_cast<double>(e - b);
    };
    const double rho = spearman(points);
    char b[320];
    std::snprintf(b, sizeof b, "| %s | %zu | %.3f | %.1f | %.1f | %.1f | %.2f |\n", region.c_str(), n,
                  points[n / 2].first, recall(2 * n / 3, n), recall(n / 3, 2 * n / 3), recall(0, n / 3), rho);
    md << b;
    results["entropy"][region] = {
        {"median", points[n / 2].first},
        {"r5m_by_tercile_sharpest_first", {recall(0, n / 3), recall(n / 3, 2 * n / 3), recall(2 * n / 3, n)}},
        {"spearman_entropy_error", rho}};
    render::Series series{region, {}, {}, true};
    for (const auto& [h, e] : points) {
      series.x.push_back(h);
      series.y.push_back(e);
    }
    const std::string picture = "entropy_scatter_" + region + ".png";
    render::write_picture(out / picture, render::plot({series}, region + ": single-frame error against entropy",
                                                      "normalized entropy of the frame's likelihood", "error (m)", 60));
    pictures << "![" << region << "](" << picture << ")\n";
  }
  md << "\n" << pictures.str();

  // 8. The simulator against the paper's failure mode: ridges along the road where the map is
  // sparse, peaks where it is dense.
  md << "\n## 8. Likelihood shape (ridge or peak; pipeline::volume_shape)\n\n"
     << "| region | frames | median elongation | ridges: elongation >= 2 along the heading (+-30°) | "
        "elongated across the heading | median major / minor sigma (m) |\n|---|---:|---:|---:|---:|---:|\n";
  for (const auto& [region, group] : regions) {
    auto& v = shapes[region];
    if (v.empty()) continue;
    std::vector<double> elongation, major, minor;
    std::size_t ridge = 0, across = 0;
    for (const auto& sh : v) {
      elongation.push_back(sh.elongation);
      major.push_back(sh.major_sigma_m);
      minor.push_back(sh.minor_sigma_m);
      if (sh.elongation >= 2 && sh.axis_to_heading_deg <= 30) ridge++;
      if (sh.elongation >= 2 && sh.axis_to_heading_deg >= 60) across++;
    }
    const auto n = static_cast<double>(v.size());
    char b[320];
    std::snprintf(b, sizeof b, "| %s (%s) | %zu | %.2f | %.1f%% | %.1f%% | %.1f / %.1f |\n", region.c_str(),
                  group.c_str(), v.size(), median(elongation), 100.0 * static_cast<double>(ridge) / n,
                  100.0 * static_cast<double>(across) / n, median(major), median(minor));
    md << b;
    results["shape"][region] = {{"median_elongation", median(elongation)},
                                {"ridge_share", static_cast<double>(ridge) / n},
                                {"across_share", static_cast<double>(across) / n}};
  }
  honesty_section(poses,
                  {"SeqLoc", "smooth (every frame given the whole route)", "SeqLoc, lag 10", "online (naive recursion)",
                   tempered_name("SeqLoc", 4)},
                  out, md, results);
  const double seconds = std::chrono::duration<double>(Clock::now() - start).count();
  md << "\nRun time " << static_cast<int>(seconds) << " s; the matcher took " << static_cast<int>(matcher_seconds)
     << " s for " << frames_matched << " frames.\n";
  std::ofstream(out / "report.md") << md.str();
  std::vector<std::string> tables_run;
  for (const auto& c : all) {
    if (std::find(tables_run.begin(), tables_run.end(), c.table) == tables_run.end()) tables_run.push_back(c.table);
  }
  results["run"] = {{"window", window},          {"threads", threads},
                    {"tables", tables_run},      {"routes_per_region", routes_per_region},
                    {"frames", frames_matched},  {"seconds", std::round(seconds)},
                    {"matcher_seconds", std::round(matcher_seconds)}};
  std::ofstream(out / "results.json") << results.dump(2) << "\n";
  std::fputs(md.str().c_str(), stdout);
  // The closing line holds the figures of the configurations that ran (a table left out by
  // --tables leaves its keys out rather than reporting zeros).
  nlohmann::ordered_json figures = {{"benchmark", "paper_tables"}, {"frames", frames_matched}};
  const auto recall = [&](const std::string& key, const std::string& config, const std::string& group, int at) {
    if (std::none_of(all.begin(), all.end(), [&](const Config& c) { return c.name == config; })) return;
    figures[key] = std::round(metrics(config, group).position_recall[static_cast<std::size_t>(at)] * 10) / 10;
  };
  const auto r5 = [&](const std::string& key, const std::string& config, const std::string& group) {
    recall(key, config, group, 2);
  };
  r5("sparse_single_r5m", "single frame", "feature-sparse");
  r5("sparse_online_r5m", "online (naive recursion)", "feature-sparse");
  r5("sparse_seqloc_r5m", "SeqLoc", "feature-sparse");
  r5("sparse_offline_r5m", "offline (+-10 frames)", "feature-sparse");
  r5("sparse_offline_all_r5m", "offline (all frames)", "feature-sparse");
  r5("urban_single_r5m", "single frame", "urban");
  r5("urban_seqloc_r5m", "SeqLoc", "urban");
  r5("sparse_seqloc_k4_r5m", tempered_name("SeqLoc", 4), "feature-sparse");
  r5("sparse_seqloc_k4_uncalibrated_r5m", tempered_name("SeqLoc without self-calibration", 4), "feature-sparse");
  r5("sparse_seqloc_k0.25_r5m", tempered_name("SeqLoc", 0.25), "feature-sparse");
  r5("sparse_seqloc_k8_r5m", tempered_name("SeqLoc", 8), "feature-sparse");
  r5("urban_online_r5m", "online (naive recursion)", "urban");
  r5("sparse_seqloc_uncalibrated_r5m", tempered_name("SeqLoc without self-calibration", 1), "feature-sparse");
  r5("urban_seqloc_uncalibrated_r5m", tempered_name("SeqLoc without self-calibration", 1), "urban");
  // R@1m beside R@5m: where a default that costs on calibrated volumes shows first.
  for (const auto& group : {std::string("sparse"), std::string("urban")}) {
    const std::string g = group == "sparse" ? "feature-sparse" : "urban";
    recall(group + "_online_r1m", "online (naive recursion)", g, 0);
    recall(group + "_seqloc_r1m", "SeqLoc", g, 0);
    recall(group + "_seqloc_uncalibrated_r1m", tempered_name("SeqLoc without self-calibration", 1), g, 0);
  }
  r5("sparse_smooth_r5m", "smooth (every frame given the whole route)", "feature-sparse");
  for (const int lag : kLags) {
    r5("sparse_lag" + std::to_string(lag) + "_r5m", "SeqLoc, lag " + std::to_string(lag), "feature-sparse");
  }
  figures["seconds"] = std::round(seconds);
  std::printf("%s\n", figures.dump().c_str());
  return 0;
}
