#include "seqloc/io/run_folder.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <sstream>

#include <nlohmann/json.hpp>

#include "seqloc/core/angles.hpp"
#include "seqloc/core/csv.hpp"
#include "seqloc/core/error.hpp"
#include "seqloc/core/files.hpp"

namespace seqloc::io {

// Strings from outside (request paths, frame ids) need not be UTF-8: replaced (U+FFFD) in JSON
// output, never a type_error thrown halfway through an answer or a run.
constexpr auto kReplaceInvalidUtf8 = nlohmann::json::error_handler_t::replace;
namespace {

std::string optional_number(const std::optional<double>& v, int precision) {
  if (!v) return "";
  char buffer[64];
  std::snprintf(buffer, sizeof buffer, "%.*f", precision, *v);
  return buffer;
}

nlohmann::ordered_json calibration_json(const UncertaintyCalibration& c) {
  nlohmann::ordered_json bins = nlohmann::json::array();
  for (std::size_t b = 0; b < c.reliability.size(); ++b) {
    const auto& bin = c.reliability[b];
    bins.push_back({{"reported_from_pct", 10 * b},
                    {"frames", bin.frames},
                    {"reported_pct", bin.reported_pct},
                    {"actual_pct", bin.actual_pct}});
  }
  return {{"frames", c.frames},
          {"coverage_95_pct", c.coverage_95_pct},
          {"mass_5m_ece_pts", c.mass_5m_ece_pts},
          {"reliability", bins}};
}

nlohmann::ordered_json metrics_json(const Metrics& m) {
  nlohmann::ordered_json j;
  j["frames_with_ground_truth"] = m.frames;
  j["position_recall_pct"] = {{"1m", m.position_recall[0]}, {"3m", m.position_recall[1]}, {"5m", m.position_recall[2]}};
  j["heading_recall_pct"] = {
      {"1deg", m.heading_recall[0]}, {"3deg", m.heading_recall[1]}, {"5deg", m.heading_recall[2]}};
  j["mean_position_error_m"] = m.mean_position_error_m;
  j["median_position_error_m"] = m.median_position_error_m;
  j["mean_heading_error_deg"] = m.mean_heading_error_deg;
  j["median_heading_error_deg"] = m.median_heading_error_deg;
  j["mean_abs_lateral_error_m"] = m.mean_abs_lateral_m;
  j["mean_abs_longitudinal_error_m"] = m.mean_abs_longitudinal_m;
  return j;
}

// poses.csv: one row per frame (docs/localize.md "Outputs").
std::string poses_csv(const RouteResult& r) {
  std::ostringstream csv;
  csv << "frame,timestamp,lat,lon,heading_deg,x_m,y_m,entropy,etu_weight,volume_power,relocalized,position_error_m,"
         "heading_error_deg,lateral_error_m,longitudinal_error_m,region,cov_xx_m2,cov_xy_m2,cov_yy_m2,heading_sd_deg,"
         "mass_5m,second_mode_share,multimodal\n";
  char line[512];
  for (const auto& p : r.poses) {
    std::snprintf(line, sizeof line, "%.6f,%.9f,%.9f,%.4f,%.3f,%.3f,%.6f,%.6f,%.6f,%d,", p.timestamp_s, p.lat_deg,
                  p.lon_deg, p.compass_heading_deg, p.x_m, p.y_m, p.entropy, p.etu_weight, p.volume_power,
                  p.relocalized ? 1 : 0);
    csv << core::csv_field(p.frame) << "," << line << optional_number(p.position_error_m, 4) << ","
        << optional_number(p.heading_error_deg, 4) << "," << optional_number(p.lateral_error_m, 4) << ","
        << optional_number(p.longitudinal_error_m, 4) << "," << core::csv_field(p.region);
    if (p.uncertainty) {
      const auto& u = *p.uncertainty;
      std::snprintf(line, sizeof line, ",%.6g,%.6g,%.6g,%.4f,%.5f,%.5f,%d", u.cov_xx_m2, u.cov_xy_m2, u.cov_yy_m2,
                    u.heading_sd_deg, u.mass_within_5m, u.second_mode_share, u.multimodal ? 1 : 0);
      csv << line << "\n";
    } else {
      csv << ",,,,,,,\n";
    }
  }
  return csv.str();
}

// trajectory.tum and groundtruth.tum: timestamp x y z qx qy qz qw in the region CRS, the yaw
// counter-clockwise from the grid's x axis (east): 90 degrees minus the grid heading. The ground
// truth has the frames whose truth has a position and a heading, at the same timestamps, so
// that `evo_ape tum groundtruth.tum trajectory.tum` needs no projection or association step.
std::pair<std::string, std::string> tum_trajectories(const RouteResult& r) {
  char line[256];
  const auto tum_line = [&line](double t, double x, double y, double grid_heading_deg) {
    const double yaw = (90.0 - grid_heading_deg) * core::kDegToRad;
    std::snprintf(line, sizeof line, "%.6f %.4f %.4f 0 0 0 %.9f %.9f\n", t, x, y, std::sin(yaw / 2), std::cos(yaw / 2));
    return std::string(line);
  };
  std::ostringstream tum, truth_tum;
  for (const auto& p : r.poses) {
    tum << tum_line(p.timestamp_s, p.x_m, p.y_m, p.grid_heading_deg);
    if (p.truth && p.truth->grid_heading_deg) {
      truth_tum << tum_line(p.timestamp_s, p.truth->x_m, p.truth->y_m, *p.truth->grid_heading_deg);
    }
  }
  return {tum.str(), truth_tum.str()};
}

// track.geojson (RFC 7946: WGS84, [lon, lat]): the estimated track, the ground-truth track when
// the route has one, and a point per frame with its values and errors.
nlohmann::ordered_json track_geojson(const RouteResult& r) {
  nlohmann::ordered_json features = nlohmann::json::array();
  nlohmann::json coordinates = nlohmann::json::array(), truth_coordinates = nlohmann::json::array();
  for (const auto& p : r.poses) {
    coordinates.push_back({p.lon_deg, p.lat_deg});
    if (p.truth) truth_coordinates.push_back({p.truth->lon_deg, p.truth->lat_deg});
  }
  features.push_back({{"type", "Feature"},
                      {"geometry", {{"type", "LineString"}, {"coordinates", coordinates}}},
                      {"properties", {{"route", r.route}, {"mode", mode_name(r.mode)}, {"track", "estimate"}}}});
  if (truth_coordinates.size() >= 2) {
    features.push_back({{"type", "Feature"},
                        {"geometry", {{"type", "LineString"}, {"coordinates", truth_coordinates}}},
                        {"properties", {{"route", r.route}, {"mode", mode_name(r.mode)}, {"track", "ground_truth"}}}});
  }
  for (const auto& p : r.poses) {
    nlohmann::ordered_json props = {{"frame", p.frame},
                                    {"timestamp", p.timestamp_s},
                                    {"heading_deg", p.compass_heading_deg},
                                    {"entropy", p.entropy},
                                    {"etu_weight", p.etu_weight},
                                    {"volume_power", p.volume_power},
                                    {"relocalized", p.relocalized}};
    if (p.position_error_m) props["position_error_m"] = *p.position_error_m;
    if (p.heading_error_deg) props["heading_error_deg"] = *p.heading_error_deg;
    if (p.lateral_error_m) props["lateral_error_m"] = *p.lateral_error_m;
    if (p.longitudinal_error_m) props["longitudinal_error_m"] = *p.longitudinal_error_m;
    if (p.truth) props["truth"] = {p.truth->lon_deg, p.truth->lat_deg};
    if (p.uncertainty) {
      const auto& u = *p.uncertainty;
      props["covariance_m2"] = {{u.cov_xx_m2, u.cov_xy_m2}, {u.cov_xy_m2, u.cov_yy_m2}};
      props["heading_sd_deg"] = u.heading_sd_deg;
      props["mass_within_5m"] = u.mass_within_5m;
      props["second_mode_share"] = u.second_mode_share;
      props["multimodal"] = u.multimodal;
    }
    features.push_back({{"type", "Feature"},
                        {"geometry", {{"type", "Point"}, {"coordinates", {p.lon_deg, p.lat_deg}}}},
                        {"properties", props}});
  }
  return {{"type", "FeatureCollection"}, {"features", features}};
}

// metrics.json: the route's recall and errors, the lag, and self-calibration's estimate.
nlohmann::ordered_json route_metrics(const RouteResult& r) {
  nlohmann::ordered_json metrics = {{"route", r.route}, {"mode", mode_name(r.mode)}, {"frames", r.poses.size()}};
  if (r.lag > 0) metrics["lag"] = r.lag;
  metrics.update(metrics_json(compute_metrics(r.poses)));
  if (const auto c = uncertainty_calibration(r.poses)) metrics["uncertainty"] = calibration_json(*c);
  if (!r.poses.empty()) {
    // Self-calibration's estimate along the route: the power of the last frame (which saw all
    // but that frame) and the median over the frames.
    std::vector<double> powers;
    for (const auto& p : r.poses) powers.push_back(p.volume_power);
    std::nth_element(powers.begin(), powers.begin() + static_cast<std::ptrdiff_t>(powers.size() / 2), powers.end());
    metrics["volume_power"] = {{"last", r.poses.back().volume_power}, {"median", powers[powers.size() / 2]}};
  }
  return metrics;
}

}  // namespace

void write_route_outputs(const std::filesystem::path& dir, const RouteResult& r) {
  core::write_file(dir / "poses.csv", poses_csv(r));
  const auto [tum, truth_tum] = tum_trajectories(r);
  core::write_file(dir / "trajectory.tum", tum);
  if (!truth_tum.empty()) core::write_file(dir / "groundtruth.tum", truth_tum);
  core::write_file(dir / "track.geojson", track_geojson(r).dump(-1, ' ', false, kReplaceInvalidUtf8) + "\n");
  core::write_file(dir / "metrics.json", route_metrics(r).dump(2, ' ', false, kReplaceInvalidUtf8) + "\n");
  if (!r.beliefs.empty()) {
    const auto frames = static_cast<int>(r.belief_origins.size());
    core::write_file(dir / "beliefs.npy",
                     encode_npy_float32(frames, r.belief_height, r.belief_width, r.beliefs.data()));
    if (r.likelihoods.size() == r.beliefs.size()) {
      core::write_file(dir / "likelihoods.npy",
                       encode_npy_float32(frames, r.belief_height, r.belief_width, r.likelihoods.data()));
    }
    std::string origins = "frame,origin_u,origin_v\n";
    for (std::size_t i = 0; i < r.belief_origins.size(); ++i) {
      origins += core::csv_field(r.poses.at(i).frame) + "," + std::to_string(r.belief_origins[i][0]) + "," +
                 std::to_string(r.belief_origins[i][1]) + "\n";
    }
    core::write_file(dir / "beliefs.csv", origins);
  }
}

std::string format_table(const MetricsByMode& metrics) {
  std::ostringstream s;
  char line[256];
  std::snprintf(line, sizeof line, "%-8s %7s %7s %7s %7s %7s %7s %7s %8s %8s %8s %8s %8s\n", "mode", "frames", "R@1m",
                "R@3m", "R@5m", "R@1deg", "R@3deg", "R@5deg", "mean m", "median m", "mean deg", "|lat| m", "|lon| m");
  s << line;
  for (const auto& [mode, m] : metrics) {
    std::snprintf(line, sizeof line, "%-8s %7zu %7.1f %7.1f %7.1f %7.1f %7.1f %7.1f %8.2f %8.2f %8.2f %8.2f %8.2f\n",
                  mode.c_str(), m.frames, m.position_recall[0], m.position_recall[1], m.position_recall[2],
                  m.heading_recall[0], m.heading_recall[1], m.heading_recall[2], m.mean_position_error_m,
                  m.median_position_error_m, m.mean_heading_error_deg, m.mean_abs_lateral_m, m.mean_abs_longitudinal_m);
    s << line;
  }
  return s.str();
}

void write_summary(const std::filesystem::path& path, const MetricsByMode& metrics,
                   const std::vector<std::string>& routes,
                   const std::map<std::string, UncertaintyCalibration>& honesty) {
  nlohmann::ordered_json j;
  j["routes"] = routes;
  for (const auto& [mode, m] : metrics) {
    j["modes"][mode] = metrics_json(m);
    if (const auto c = honesty.find(mode); c != honesty.end())
      j["modes"][mode]["uncertainty"] = calibration_json(c->second);
  }
  core::write_file(path, j.dump(2, ' ', false, kReplaceInvalidUtf8) + "\n");
}

std::vector<FramePose> read_poses_csv(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw DataError(path.string() + ": cannot open");
  core::CsvReader csv(in, path.string());
  std::vector<FramePose> poses;
  int line = 0;
  auto number = [&](const std::string& s) -> std::optional<double> {
    if (s.empty()) return std::nullopt;
    try {
      std::size_t used = 0;
      const double v = std::stod(s, &used);
      if (used != s.size()) throw std::invalid_argument(s);
      return v;
    } catch (const std::exception&) {
      throw DataError(path.string() + ":" + std::to_string(line) + ": '" + s + "' is not a number");
    }
  };
  bool with_uncertainty = false;  // the header names the uncertainty's columns (after the region)
  while (auto record = csv.next()) {
    line = record->line;
    std::vector<std::string>& f = record->fields;
    if (line == 1) {  // the header
      with_uncertainty = f.size() == 23 && f[22] == "multimodal";
      continue;
    }
    if (with_uncertainty) {
      if (f.size() != 23) {
        throw DataError(path.string() + ":" + std::to_string(line) + ": " + std::to_string(f.size()) +
                        " fields, expected 23 (a poses.csv written by seqloc localize)");
      }
    } else {
      // 16 fields, the region last; 15 in files written before the region was, 14 before
      // volume_power was (read as power 1). In files written before fields were quoted, a region
      // name with commas stands unquoted: its parts are joined again.
      if (f.size() == 14) f.insert(f.begin() + 9, "1");
      if (f.size() > 16) {
        for (std::size_t i = 16; i < f.size(); ++i) f[15] += "," + f[i];
        f.resize(16);
      }
      if (f.size() != 15 && f.size() != 16) {
        throw DataError(path.string() + ":" + std::to_string(line) + ": " + std::to_string(f.size()) +
                        " fields, expected 16 (a poses.csv written by seqloc localize)");
      }
    }
    FramePose p;
    p.frame = f[0];
    p.timestamp_s = number(f[1]).value_or(0);
    p.lat_deg = number(f[2]).value_or(0);
    p.lon_deg = number(f[3]).value_or(0);
    p.compass_heading_deg = number(f[4]).value_or(0);
    p.x_m = number(f[5]).value_or(0);
    p.y_m = number(f[6]).value_or(0);
    p.entropy = number(f[7]).value_or(0);
    p.etu_weight = number(f[8]).value_or(0);
    p.volume_power = number(f[9]).value_or(1);
    p.relocalized = f[10] == "1";
    p.position_error_m = number(f[11]);
    p.heading_error_deg = number(f[12]);
    p.lateral_error_m = number(f[13]);
    p.longitudinal_error_m = number(f[14]);
    if (f.size() >= 16) p.region = f[15];
    if (with_uncertainty && !f[16].empty()) {
      FramePose::Uncertainty u;
      u.cov_xx_m2 = number(f[16]).value_or(0);
      u.cov_xy_m2 = number(f[17]).value_or(0);
      u.cov_yy_m2 = number(f[18]).value_or(0);
      u.heading_sd_deg = number(f[19]).value_or(0);
      u.mass_within_5m = number(f[20]).value_or(0);
      u.second_mode_share = number(f[21]).value_or(0);
      u.multimodal = f[22] == "1";
      p.uncertainty = u;
    }
    poses.push_back(std::move(p));
  }
  return poses;
}

RunFolderWriter::RunFolderWriter(std::filesystem::path root)
    : root_(std::move(root)), staged_(core::staging_directory(root_)) {
  std::error_code ec;
  std::filesystem::create_directories(staged_, ec);
  if (ec) throw IoError(staged_.string() + ": cannot create: " + ec.message());
}

RunFolderWriter::~RunFolderWriter() {
  if (committed_) return;
  std::error_code ec;
  std::filesystem::remove_all(staged_, ec);
}

std::filesystem::path RunFolderWriter::add(const RouteResult& result) {
  const std::filesystem::path dir = staged_ / result.route / mode_name(result.mode);
  std::error_code ec;
  std::filesystem::create_directories(dir, ec);
  if (ec) throw IoError(dir.string() + ": cannot create: " + ec.message());
  write_route_outputs(dir, result);
  auto& all = poses_by_mode_[mode_name(result.mode)];
  all.insert(all.end(), result.poses.begin(), result.poses.end());
  return dir;
}

MetricsByMode RunFolderWriter::commit(const std::vector<std::string>& routes) {
  MetricsByMode metrics;
  std::map<std::string, UncertaintyCalibration> honesty;
  for (const auto& [mode, poses] : poses_by_mode_) {
    metrics[mode] = compute_metrics(poses);
    if (const auto c = uncertainty_calibration(poses)) honesty[mode] = *c;
  }
  write_summary(staged_ / "summary.json", metrics, routes, honesty);
  // Into place: the old folder (if any) is replaced only once the new one is complete.
  core::commit_directory(staged_, root_);
  committed_ = true;
  return metrics;
}

std::vector<PosesFile> find_poses_files(const std::vector<std::filesystem::path>& folders) {
  namespace fs = std::filesystem;
  std::map<fs::path, std::string> files;  // canonical path -> mode
  for (const auto& out : folders) {
    std::error_code ec;
    if (!fs::is_directory(out, ec)) throw DataError(out.string() + ": not an output folder");
    const auto add = [&files](const fs::path& poses) {
      std::error_code e;
      if (fs::is_regular_file(poses, e)) files.emplace(fs::canonical(poses), poses.parent_path().filename().string());
    };
    // A poses.csv at most two levels under each folder given; its mode is its folder's name.
    add(out / "poses.csv");
    for (const auto& child : fs::directory_iterator(out)) {
      if (!child.is_directory()) continue;
      add(child.path() / "poses.csv");
      for (const auto& grandchild : fs::directory_iterator(child.path())) {
        if (grandchild.is_directory()) add(grandchild.path() / "poses.csv");
      }
    }
  }
  if (files.empty()) throw DataError("no poses.csv found in or under the given folders");
  std::vector<PosesFile> found;
  found.reserve(files.size());
  for (const auto& [path, mode] : files) found.push_back({path, mode});
  return found;
}

MetricsByMode evaluate_poses_files(const std::vector<PosesFile>& files) {
  std::map<std::string, std::vector<FramePose>> by_mode;
  for (const auto& file : files) {
    auto read = read_poses_csv(file.path);
    auto& all = by_mode[file.mode];
    all.insert(all.end(), read.begin(), read.end());
  }
  MetricsByMode metrics;
  for (const auto& [mode, poses] : by_mode) metrics[mode] = compute_metrics(poses);
  return metrics;
}

KeptBeliefs::KeptBeliefs(const std::filesystem::path& dir, std::size_t frames) : npy_(dir / "beliefs.npy") {
  if (npy_.type() != core::VolumeType::float32 || static_cast<std::size_t>(npy_.extent(0)) != frames) {
    throw DataError((dir / "beliefs.npy").string() + ": expected float32 beliefs of " + std::to_string(frames) +
                    " frames (the route's), found " + std::to_string(npy_.extent(0)));
  }
  const auto path = dir / "beliefs.csv";
  std::ifstream in(path);
  core::CsvReader csv(in, path.string());
  const auto header = in ? csv.next() : std::nullopt;
  if (!header || header->fields != std::vector<std::string>{"frame", "origin_u", "origin_v"}) {
    throw DataError(path.string() + ": missing, or not a beliefs.csv (header frame,origin_u,origin_v)");
  }
  while (const auto record = csv.next()) {
    const auto integer = [&](const std::string& text) {
      std::int64_t value = 0;
      const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
      if (text.empty() || error != std::errc() || end != text.data() + text.size()) {
        throw DataError(path.string() + ":" + std::to_string(record->line) + ": expected frame,origin_u,origin_v");
      }
      return value;
    };
    // The origins are the last two fields (an id with commas written unquoted by an older seqloc
    // spans several).
    const auto& f = record->fields;
    if (f.size() < 3) integer("");
    origins_.push_back({integer(f[f.size() - 2]), integer(f[f.size() - 1])});
  }
  if (origins_.size() != frames) {
    throw DataError(path.string() + ": " + std::to_string(origins_.size()) + " rows for a route of " +
                    std::to_string(frames) + " frames");
  }
  const auto likelihoods = dir / "likelihoods.npy";
  std::error_code ec;
  if (std::filesystem::exists(likelihoods, ec)) {
    likelihoods_.emplace(likelihoods);
    if (likelihoods_->type() != core::VolumeType::float32 || likelihoods_->extent(0) != npy_.extent(0) ||
        likelihoods_->extent(1) != npy_.extent(1) || likelihoods_->extent(2) != npy_.extent(2)) {
      throw DataError(likelihoods.string() + ": expected float32 of beliefs.npy's shape (" +
                      std::to_string(npy_.extent(0)) + ", " + std::to_string(npy_.extent(1)) + ", " +
                      std::to_string(npy_.extent(2)) + ")");
    }
  } else {
    likelihoods_path_ = likelihoods;
  }
}

std::vector<double> KeptBeliefs::marginal(std::size_t frame) const {
  const std::size_t cells = static_cast<std::size_t>(width()) * static_cast<std::size_t>(height());
  const float* p = static_cast<const float*>(npy_.data()) + frame * cells;
  return {p, p + cells};
}

std::vector<double> KeptBeliefs::likelihood(std::size_t frame) const {
  if (!likelihoods_) {
    throw DataError(likelihoods_path_.string() +
                    ": missing (a run of an older seqloc); run seqloc localize --beliefs again to keep the frames' "
                    "likelihoods");
  }
  const std::size_t cells = static_cast<std::size_t>(width()) * static_cast<std::size_t>(height());
  const float* p = static_cast<const float*>(likelihoods_->data()) + frame * cells;
  return {p, p + cells};
}

bool RunFolder::has_route(const std::string& route) const {
  std::error_code ec;
  return std::filesystem::is_directory(root_ / route, ec);
}

std::vector<std::pair<Mode, std::vector<FramePose>>> RunFolder::route_poses(const std::string& route) const {
  std::vector<std::pair<Mode, std::vector<FramePose>>> poses;
  for (const Mode mode : kModes) {
    const auto path = mode_dir(route, mode) / "poses.csv";
    std::error_code ec;
    if (std::filesystem::is_regular_file(path, ec)) poses.emplace_back(mode, read_poses_csv(path));
  }
  return poses;
}

bool RunFolder::has_beliefs(const std::string& route, Mode mode) const {
  std::error_code ec;
  return std::filesystem::is_regular_file(mode_dir(route, mode) / "beliefs.npy", ec);
}

}  // namespace seqloc::io
