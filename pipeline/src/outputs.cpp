#include "seqloc/pipeline/outputs.hpp"

#include <fcntl.h>  // AT_FDCWD
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cmath>
#include <csignal>  // ::kill (POSIX)
#include <cstdio>   // ::renameat2, RENAME_EXCHANGE (glibc)
#include <cstring>
#include <fstream>

#include <nlohmann/json.hpp>

#include "seqloc/pipeline/npy.hpp"

namespace seqloc::pipeline {

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

nlohmann::ordered_json metrics_json(const Metrics& m) {
  nlohmann::ordered_json j;
  j["frames_with_ground_truth"] = m.frames;
  j["position_recall_pct"] = {{"1m", m.position_recall[0]}, {"3m", m.position_recall[1]}, {"5m", m.position_recall[2]}};
  j["heading_recall_pct"] = {{"1deg", m.heading_recall[0]}, {"3deg", m.heading_recall[1]}, {"5deg", m.heading_recall[2]}};
  j["mean_position_error_m"] = m.mean_position_error_m;
  j["median_position_error_m"] = m.median_position_error_m;
  j["mean_heading_error_deg"] = m.mean_heading_error_deg;
  j["median_heading_error_deg"] = m.median_heading_error_deg;
  j["mean_abs_lateral_error_m"] = m.mean_abs_lateral_m;
  j["mean_abs_longitudinal_error_m"] = m.mean_abs_longitudinal_m;
  return j;
}

}  // namespace

void write_file(const std::filesystem::path& path, const std::string& bytes) {
  const std::filesystem::path tmp = path.string() + ".tmp";
  {
    std::ofstream out(tmp, std::ios::binary);
    out << bytes;
    out.close();
    if (!out) throw DataError(path.string() + ": cannot write");
  }
  std::error_code ec;
  std::filesystem::rename(tmp, path, ec);
  if (ec) throw DataError(path.string() + ": cannot write: " + ec.message());
}

void commit_directory(const std::filesystem::path& staged, const std::filesystem::path& target) {
  auto fail = [&](const std::string& why) {
    throw DataError(target.string() + ": cannot move the finished output into place: " + why);
  };
  std::error_code ec;
  if (::renameat2(AT_FDCWD, staged.c_str(), AT_FDCWD, target.c_str(), RENAME_EXCHANGE) == 0) {
    std::filesystem::remove_all(staged, ec);  // the previous folder; a leftover is removed next run
    return;
  }
  const int exchange_error = errno;
  if (exchange_error == ENOENT && std::filesystem::exists(staged, ec)) {
    // No target yet: a plain rename, atomic too.
    std::filesystem::rename(staged, target, ec);
    if (ec) fail(ec.message());
    return;
  }
  if (exchange_error != EINVAL && exchange_error != ENOSYS) fail(std::strerror(exchange_error));
  // A file system without RENAME_EXCHANGE: two renames, with a short window in which `target`
  // is missing and the previous folder sits beside it as TARGET.old.
  const std::filesystem::path old = target.string() + ".old";
  std::filesystem::remove_all(old, ec);
  std::filesystem::rename(target, old, ec);
  if (!ec) std::filesystem::rename(staged, target, ec);
  if (ec) fail(ec.message());
  std::filesystem::remove_all(old, ec);
}

std::filesystem::path staging_directory(const std::filesystem::path& target) {
  const std::string prefix = target.filename().string() + ".partial-";
  std::filesystem::path parent = target.parent_path();
  if (parent.empty()) parent = ".";
  std::error_code ec;
  for (const auto& entry : std::filesystem::directory_iterator(parent, ec)) {
    const std::string name = entry.path().filename().string();
    if (name.rfind(prefix, 0) != 0) continue;
    const std::string digits = name.substr(prefix.size());
    if (digits.empty() || digits.find_first_not_of("0123456789") != std::string::npos || digits.size() > 9) continue;
    const auto pid = static_cast<pid_t>(std::stol(digits));
    if (pid != ::getpid() && ::kill(pid, 0) != 0 && errno == ESRCH) std::filesystem::remove_all(entry.path(), ec);
  }
  std::filesystem::path staged = target.string() + ".partial-" + std::to_string(::getpid());
  std::filesystem::remove_all(staged, ec);
  return staged;
}

namespace {

// poses.csv: one row per frame (docs/localize.md "Outputs").
std::string poses_csv(const RouteResult& r) {
  std::ostringstream csv;
  csv << "frame,timestamp,lat,lon,heading_deg,x_m,y_m,entropy,etu_weight,volume_power,relocalized,position_error_m,"
         "heading_error_deg,lateral_error_m,longitudinal_error_m,region\n";
  char line[512];
  for (const auto& p : r.poses) {
    std::snprintf(line, sizeof line, "%.6f,%.9f,%.9f,%.4f,%.3f,%.3f,%.6f,%.6f,%.6f,%d,", p.timestamp_s, p.lat_deg,
                  p.lon_deg, p.compass_heading_deg, p.x_m, p.y_m, p.entropy, p.etu_weight, p.volume_power,
                  p.relocalized ? 1 : 0);
    csv << p.frame << "," << line << optional_number(p.position_error_m, 4) << ","
        << optional_number(p.heading_error_deg, 4) << "," << optional_number(p.lateral_error_m, 4) << ","
        << optional_number(p.longitudinal_error_m, 4) << "," << p.region << "\n";
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
    const double yaw = (90.0 - grid_heading_deg) * M_PI / 180.0;
    std::snprintf(line, sizeof line, "%.6f %.4f %.4f 0 0 0 %.9f %.9f\n", t, x, y, std::sin(yaw / 2),
                  std::cos(yaw / 2));
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
    nlohmann::ordered_json props = {{"frame", p.frame},         {"timestamp", p.timestamp_s},
                                    {"heading_deg", p.compass_heading_deg}, {"entropy", p.entropy},
                                    {"etu_weight", p.etu_weight}, {"volume_power", p.volume_power},
                                    {"relocalized", p.relocalized}};
    if (p.position_error_m) props["position_error_m"] = *p.position_error_m;
    if (p.heading_error_deg) props["heading_error_deg"] = *p.heading_error_deg;
    if (p.lateral_error_m) props["lateral_error_m"] = *p.lateral_error_m;
    if (p.longitudinal_error_m) props["longitudinal_error_m"] = *p.longitudinal_error_m;
    if (p.truth) props["truth"] = {p.truth->lon_deg, p.truth->lat_deg};
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
  write_file(dir / "poses.csv", poses_csv(r));
  const auto [tum, truth_tum] = tum_trajectories(r);
  write_file(dir / "trajectory.tum", tum);
  if (!truth_tum.empty()) write_file(dir / "groundtruth.tum", truth_tum);
  write_file(dir / "track.geojson", track_geojson(r).dump(-1, ' ', false, kReplaceInvalidUtf8) + "\n");
  write_file(dir / "metrics.json", route_metrics(r).dump(2, ' ', false, kReplaceInvalidUtf8) + "\n");
  if (!r.beliefs.empty()) {
    const auto frames = static_cast<int>(r.belief_origins.size());
    write_file(dir / "beliefs.npy", encode_npy_float32(frames, r.belief_height, r.belief_width, r.beliefs.data()));
    std::string origins = "frame,origin_u,origin_v\n";
    for (std::size_t i = 0; i < r.belief_origins.size(); ++i) {
      origins += r.poses.at(i).frame + "," + std::to_string(r.belief_origins[i][0]) + "," +
                 std::to_string(r.belief_origins[i][1]) + "\n";
    }
    write_file(dir / "beliefs.csv", origins);
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

void write_summary(const std::filesystem::path& path, const MetricsByMode& metrics, const std::vector<std::string>& routes) {
  nlohmann::ordered_json j;
  j["routes"] = routes;
  for (const auto& [mode, m] : metrics) j["modes"][mode] = metrics_json(m);
  write_file(path, j.dump(2, ' ', false, kReplaceInvalidUtf8) + "\n");
}

std::vector<FramePose> read_poses_csv(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw DataError(path.string() + ": cannot open");
  std::string text;
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
  while (std::getline(in, text)) {
    ++line;
    if (line == 1 || text.empty()) continue;
    std::vector<std::string> f;
    std::stringstream ss(text);
    std::string cell;
    while (std::getline(ss, cell, ',')) f.push_back(cell);
    if (!text.empty() && text.back() == ',') f.emplace_back();
    // 16 fields, the region last (its name may hold commas); 15 in files written before the
    // region was, 14 before volume_power was (read as power 1).
    if (f.size() == 14) f.insert(f.begin() + 9, "1");
    if (f.size() > 16) {
      for (std::size_t i = 16; i < f.size(); ++i) f[15] += "," + f[i];
      f.resize(16);
    }
    if (f.size() != 15 && f.size() != 16) {
      throw DataError(path.string() + ":" + std::to_string(line) + ": " + std::to_string(f.size()) +
                      " fields, expected 16 (a poses.csv written by seqloc localize)");
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
    if (f.size() == 16) p.region = f[15];
    poses.push_back(std::move(p));
  }
  return poses;
}

}  // namespace seqloc::pipeline
