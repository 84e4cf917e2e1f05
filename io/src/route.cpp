#include "seqloc/io/route.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <cstring>
#include <fstream>
#include <map>
#include <set>

#include <nlohmann/json.hpp>

#include "seqloc/core/csv.hpp"
#include "seqloc/io/npy.hpp"

namespace seqloc::io {
namespace {

const std::set<std::string>& known_columns() {
  static const std::set<std::string> columns{"frame",       "timestamp",     "volume",  "observation",   "crop_lat",
                                             "crop_lon",    "crop_x",        "crop_y",  "odo_forward_m", "odo_left_m",
                                             "odo_yaw_deg", "gps_lat",       "gps_lon", "gps_sigma_m",   "gt_lat",
                                             "gt_lon",      "gt_heading_deg"};
  return columns;
}

}  // namespace

void RouteLimits::validate() const {
  auto fail = [](const std::string& field, double value, const char* constraint) {
    std::ostringstream s;
    s << "route limits: " << field << " = " << value << ": " << constraint;
    throw UsageError(s.str());
  };
  if (!(max_step_m > 0)) fail("max_step_m", max_step_m, "must be > 0");
  if (!(max_speed_mps > 0)) fail("max_speed_mps", max_speed_mps, "must be > 0");
  if (!(max_yaw_deg > 0 && max_yaw_deg <= 360)) fail("max_yaw_deg", max_yaw_deg, "must be in (0, 360]");
}

namespace {

// Throws DataError naming the file and the line.
struct LineError {
  std::filesystem::path file;
  [[noreturn]] void operator()(int line, const std::string& what) const {
    throw DataError(file.string() + ":" + std::to_string(line) + ": " + what);
  }
};

// route.json: the route's name, volume kind, layout and cell size into `route`.
void read_route_json(const std::filesystem::path& dir, Route& route) {
  const auto json_path = dir / "route.json";
  std::ifstream json_in(json_path);
  if (!json_in) throw DataError(json_path.string() + ": missing (every route directory has route.json)");
  nlohmann::json meta;
  try {
    meta = nlohmann::json::parse(json_in);
  } catch (const nlohmann::json::exception& e) {
    throw DataError(json_path.string() + ": not valid JSON: " + e.what());
  }
  auto meta_fail = [&](const std::string& what) { throw DataError(json_path.string() + ": " + what); };
  if (!meta.is_object()) meta_fail("not a JSON object");
  // Unknown keys are errors: a misspelt "volume_knd" would otherwise be read as the default.
  // "simulated" is the provenance `seqloc simulate` records (read by no one, kept for people).
  static const std::set<std::string> kKnownKeys{"format", "version", "name",     "volume_kind",
                                                "cell_m", "layout",  "simulated"};
  for (const auto& [key, value] : meta.items()) {
    if (!kKnownKeys.count(key)) {
      meta_fail("unknown key \"" + key + "\" (known: format, version, name, volume_kind, cell_m, layout, simulated)");
    }
  }
  // A member of the expected type, or the fallback when it is absent; any other type is an error
  // naming the member (json::value would throw a type_error that names nothing).
  auto string_member = [&](const char* key, const char* fallback) -> std::string {
    const auto it = meta.find(key);
    if (it == meta.end()) return fallback;
    if (!it->is_string()) meta_fail(std::string("\"") + key + "\" must be a string");
    return it->get<std::string>();
  };
  if (string_member("format", "") != "seqloc-route") meta_fail(R"("format" must be "seqloc-route")");
  // Compared as a JSON number: 4294967297 is not 1, as a cast to int would make it.
  if (!meta.contains("version") || !meta["version"].is_number_integer() || meta["version"] != 1) {
    meta_fail(R"("version" must be 1 (this seqloc reads route format 1))");
  }
  route.name = string_member("name", dir.filename().string().c_str());
  const std::string kind = string_member("volume_kind", "log_prob");
  if (kind == "log_prob") {
    route.volume_kind = core::VolumeValues::log_prob;
  } else if (kind == "prob") {
    route.volume_kind = core::VolumeValues::prob;
  } else {
    meta_fail(R"("volume_kind" must be "log_prob" or "prob", not ")" + kind + "\"");
  }
  const std::string layout = string_member("layout", "");
  if (layout == "HWN" || layout == "NHW") {
    route.layout = layout == "HWN" ? VolumeLayout::hwn : VolumeLayout::nhw;
    route.layout_declared = true;
  } else if (!layout.empty() || meta.contains("layout")) {
    meta_fail(R"("layout" must be "HWN" or "NHW", not ")" + layout + "\"");
  }
  if (meta.contains("cell_m")) {
    if (!meta["cell_m"].is_number() || !(meta["cell_m"].get<double>() > 0)) meta_fail("\"cell_m\" must be > 0");
    route.cell_m = meta["cell_m"].get<double>();
  }
  if (meta.contains("simulated")) route.simulated_json = meta["simulated"].dump();
}

using Columns = std::map<std::string, std::size_t>;

// frames.csv's header: each column's index, checked for what a route needs.
Columns read_header(const std::vector<std::string>& fields, int line, const LineError& fail) {
  Columns column;
  for (std::size_t i = 0; i < fields.size(); ++i) {
    if (!known_columns().count(fields[i])) fail(line, "unknown column '" + fields[i] + "'");
    if (column.count(fields[i])) fail(line, "column '" + fields[i] + "' appears twice");
    column[fields[i]] = i;
  }
  auto need = [&](std::initializer_list<const char*> all, const char* what) {
    for (const char* c : all) {
      if (!column.count(c)) fail(line, std::string("missing column '") + c + "' (" + what + ")");
    }
  };
  need({"frame", "timestamp", "odo_forward_m", "odo_left_m", "odo_yaw_deg"}, "required");
  if (column.count("volume") == column.count("observation")) {
    fail(line, "exactly one of the columns 'volume' and 'observation' is needed");
  }
  const bool geo = column.count("crop_lat") || column.count("crop_lon");
  const bool grid = column.count("crop_x") || column.count("crop_y");
  if (geo == grid) fail(line, "the crop needs either 'crop_lat, crop_lon' or 'crop_x, crop_y'");
  if (geo) need({"crop_lat", "crop_lon"}, "crop as lat/lon");
  if (grid) need({"crop_x", "crop_y"}, "crop in grid coordinates");
  if (column.count("gps_lat") || column.count("gps_lon") || column.count("gps_sigma_m")) {
    need({"gps_lat", "gps_lon", "gps_sigma_m"}, "GPS prior");
  }
  if (column.count("gt_lat") || column.count("gt_lon") || column.count("gt_heading_deg")) {
    need({"gt_lat", "gt_lon"}, "ground truth");
  }
  return column;
}

// One row of frames.csv (as many fields as the header) into a frame; its file must exist.
RouteFrame read_frame_row(const std::vector<std::string>& fields, const Columns& column, int line,
                          const std::filesystem::path& dir, const LineError& fail) {
  auto field = [&](const char* name) -> const std::string& { return fields[column.at(name)]; };
  auto has = [&](const char* name) { return column.count(name) && !fields[column.at(name)].empty(); };
  auto number = [&](const char* name) {
    const std::string& s = field(name);
    double value = 0;
    const auto [end, error] = std::from_chars(s.data(), s.data() + s.size(), value);
    if (s.empty() || error != std::errc() || end != s.data() + s.size() || !std::isfinite(value)) {
      fail(line, std::string(name) + " '" + s + "' is not a finite number");
    }
    return value;
  };
  RouteFrame f;
  f.line = line;
  f.frame = field("frame");
  if (f.frame.empty()) fail(line, "empty frame id");
  f.timestamp_s = number("timestamp");
  const char* data_column = column.count("volume") ? "volume" : "observation";
  const std::string& relative = field(data_column);
  if (relative.empty()) fail(line, std::string("empty ") + data_column + " path");
  const auto absolute =
      std::filesystem::path(relative).is_absolute() ? std::filesystem::path(relative) : dir / relative;
  std::error_code ec;
  if (!std::filesystem::is_regular_file(absolute, ec)) {
    fail(line, std::string(data_column) + " '" + relative + "' does not exist");
  }
  (column.count("volume") ? f.volume : f.observation) = absolute;
  if (column.count("crop_lat")) {
    f.crop_geo = osm::GeoPoint{number("crop_lat"), number("crop_lon")};
    if (std::abs(f.crop_geo->lat_deg) > 90 || std::abs(f.crop_geo->lon_deg) > 180) {
      fail(line, "crop_lat/crop_lon outside [-90, 90] x [-180, 180]");
    }
  } else {
    f.crop_grid = osm::GridPoint{number("crop_x"), number("crop_y")};
  }
  f.odometry = {number("odo_forward_m"), number("odo_left_m"), number("odo_yaw_deg")};
  if (has("gps_lat") || has("gps_lon") || has("gps_sigma_m")) {
    f.gps = GpsPrior{{number("gps_lat"), number("gps_lon")}, number("gps_sigma_m")};
    if (!(f.gps->sigma_m > 0)) fail(line, "gps_sigma_m must be > 0");
  }
  if (has("gt_lat") || has("gt_lon")) {
    f.truth = GroundTruth{{number("gt_lat"), number("gt_lon")}, std::nullopt};
    if (has("gt_heading_deg")) f.truth->heading_deg = number("gt_heading_deg");
  }
  return f;
}

// The motion from the previous frame (none for the first): later in time, within the limits.
void check_motion(const RouteFrame* previous, const RouteFrame& f, const std::string& timestamp,
                  const RouteLimits& limits, const LineError& fail) {
  if (!previous) {
    if (f.odometry.forward_m != 0 || f.odometry.left_m != 0 || f.odometry.yaw_deg != 0) {
      fail(f.line, "the first frame's odometry must be 0 (it is the motion from the previous frame)");
    }
    return;
  }
  const double dt = f.timestamp_s - previous->timestamp_s;
  if (!(dt > 0)) {
    fail(f.line, "timestamp " + timestamp + " does not come after the previous frame's (line " +
                     std::to_string(previous->line) + ")");
  }
  const double step = std::hypot(f.odometry.forward_m, f.odometry.left_m);
  std::ostringstream why;
  if (step > limits.max_step_m) {
    why << "odometry step of " << step << " m exceeds the limit of " << limits.max_step_m << " m";
  } else if (step / dt > limits.max_speed_mps) {
    why << "odometry step of " << step << " m in " << dt << " s is " << step / dt << " m/s, above the limit of "
        << limits.max_speed_mps << " m/s";
  } else if (std::abs(f.odometry.yaw_deg) > limits.max_yaw_deg) {
    why << "odometry yaw of " << f.odometry.yaw_deg << " degrees exceeds the limit of " << limits.max_yaw_deg;
  }
  if (!why.str().empty()) fail(f.line, why.str());
}

}  // namespace

void check_volume_layout(const Route& route, const RouteFrame& f, const NpyVolume& npy) {
  if (route.layout != VolumeLayout::hwn || route.layout_declared) return;
  if (npy.width() != npy.bins() || npy.height() == npy.width()) return;
  const std::string shape =
      "(" + std::to_string(npy.height()) + ", " + std::to_string(npy.width()) + ", " + std::to_string(npy.bins()) + ")";
  throw DataError(f.volume.string() + " (frames.csv line " + std::to_string(f.line) + "): shape " + shape +
                  " looks like (N, H, W), headings first and a square crop " +
                  R"(last, but volumes are read as (H, W, N); set "layout": "NHW" in route.json (or )" +
                  R"("layout": "HWN" if )" + shape + " is H, W, N)");
}

core::FrameVolume frame_volume(const Route& route, const RouteFrame& f, const NpyVolume& npy,
                               std::vector<unsigned char>& buffer) {
  check_volume_layout(route, f, npy);
  if (route.layout == VolumeLayout::hwn) return npy.view(route.volume_kind, route.cell_m);
  const int n = npy.height(), h = npy.width(), w = npy.bins();
  const std::size_t element = npy.type() == core::VolumeType::float16 ? 2 : 4;
  const auto cells = static_cast<std::size_t>(n) * static_cast<std::size_t>(h) * static_cast<std::size_t>(w);
  buffer.resize(cells * element);
  const auto* source = static_cast<const unsigned char*>(npy.data());
  std::size_t from = 0;  // (k, y, x) in C order
  for (std::size_t k = 0; k < static_cast<std::size_t>(n); ++k) {
    for (std::size_t yx = 0; yx < static_cast<std::size_t>(h) * static_cast<std::size_t>(w); ++yx, ++from) {
      std::memcpy(buffer.data() + (yx * static_cast<std::size_t>(n) + k) * element, source + from * element, element);
    }
  }
  return {buffer.data(), npy.type(), route.volume_kind, h, w, n, route.cell_m};
}

Route read_route(const std::filesystem::path& dir, const RouteLimits& limits) {
  limits.validate();
  Route route;
  route.dir = dir;
  std::error_code ec;
  if (!std::filesystem::is_directory(dir, ec)) throw DataError(dir.string() + ": not a route directory");
  read_route_json(dir, route);

  const auto csv_path = dir / "frames.csv";
  std::ifstream csv(csv_path);
  if (!csv) throw DataError(csv_path.string() + ": missing (every route directory has frames.csv)");
  const LineError fail{csv_path};
  core::CsvReader reader(csv, csv_path.string(), {.trim_blanks = true});
  Columns column;
  while (const auto record = reader.next()) {
    const std::vector<std::string>& fields = record->fields;
    const int line = record->line;
    if (column.empty()) {
      column = read_header(fields, line, fail);
      continue;
    }
    if (fields.size() != column.size()) {
      fail(line, std::to_string(fields.size()) + " fields, but the header has " + std::to_string(column.size()));
    }
    RouteFrame f = read_frame_row(fields, column, line, dir, fail);
    check_motion(route.frames.empty() ? nullptr : &route.frames.back(), f, fields[column.at("timestamp")], limits,
                 fail);
    route.frames.push_back(std::move(f));
  }
  if (column.empty()) throw DataError(csv_path.string() + ": empty (a header row and one row per frame are needed)");
  if (route.frames.empty()) throw DataError(csv_path.string() + ": no frames after the header");
  return route;
}

std::vector<Route> read_routes(std::vector<std::filesystem::path> dirs, const RouteLimits& limits, const Shard& shard,
                               const std::function<void(const Route&)>& check_other) {
  std::sort(dirs.begin(), dirs.end());
  std::vector<Route> routes;
  std::set<std::string> names;
  for (std::size_t k = 0; k < dirs.size(); ++k) {
    Route route = read_route(dirs[k], limits);
    // Two folders of one name (from different parents) keep apart in the output.
    if (!names.insert(route.name).second) route.name += "-" + std::to_string(k + 1);
    names.insert(route.name);
    if (static_cast<int>(k % static_cast<std::size_t>(std::max(1, shard.count))) != shard.index) {
      if (check_other) check_other(route);
      continue;
    }
    routes.push_back(std::move(route));
  }
  return routes;
}

std::size_t frame_count(const std::vector<Route>& routes) {
  std::size_t n = 0;
  for (const auto& route : routes) n += route.frames.size();
  return n;
}

namespace {

// The shortest text that reads back as the same double.
std::string shortest(double v) {
  char buffer[32];
  const auto [end, ec] = std::to_chars(buffer, buffer + sizeof buffer, v);
  return ec == std::errc() ? std::string(buffer, end) : std::string("nan");
}

// `path` relative to `dir` when it lies under it, else as it is.
std::string route_path(const std::filesystem::path& path, const std::filesystem::path& dir) {
  std::error_code ec;
  const auto relative = std::filesystem::relative(path, dir, ec);
  if (!ec && !relative.empty() && *relative.begin() != "..") return relative.generic_string();
  return path.string();
}

}  // namespace

void write_route(const Route& route, const std::filesystem::path& dir) {
  // frames.csv has one data column and one kind of crop for all its rows: a frame of another kind
  // cannot be written without losing it.
  const bool observations = !route.frames.empty() && !route.frames.front().observation.empty();
  const bool geo = !route.frames.empty() && route.frames.front().crop_geo.has_value();
  for (const RouteFrame& f : route.frames) {
    if (f.observation.empty() == observations || f.crop_geo.has_value() != geo || f.crop_grid.has_value() == geo) {
      throw DataError((dir / "frames.csv").string() + ": frame '" + f.frame +
                      "' differs from the first in its data (volume or observation) or its crop (lat/lon or grid); "
                      "a route holds one kind of each");
    }
  }
  std::filesystem::create_directories(dir);
  nlohmann::ordered_json meta = {{"format", "seqloc-route"},
                                 {"version", 1},
                                 {"name", route.name},
                                 {"volume_kind", route.volume_kind == core::VolumeValues::prob ? "prob" : "log_prob"},
                                 {"cell_m", route.cell_m}};
  if (route.layout_declared) meta["layout"] = route.layout == VolumeLayout::nhw ? "NHW" : "HWN";
  if (!route.simulated_json.empty()) meta["simulated"] = nlohmann::ordered_json::parse(route.simulated_json);
  std::ofstream json(dir / "route.json");
  json << meta.dump(2) << '\n';
  if (!json.flush()) throw DataError((dir / "route.json").string() + ": cannot write");

  auto any = [&](auto has) { return std::any_of(route.frames.begin(), route.frames.end(), has); };
  const bool gps = any([](const RouteFrame& f) { return f.gps.has_value(); });
  const bool truth = any([](const RouteFrame& f) { return f.truth.has_value(); });
  const bool heading = any([](const RouteFrame& f) { return f.truth && f.truth->heading_deg; });
  std::ofstream csv(dir / "frames.csv");
  csv << "frame,timestamp," << (observations ? "observation" : "volume")
      << (geo ? ",crop_lat,crop_lon" : ",crop_x,crop_y") << ",odo_forward_m,odo_left_m,odo_yaw_deg"
      << (gps ? ",gps_lat,gps_lon,gps_sigma_m" : "") << (truth ? ",gt_lat,gt_lon" : "")
      << (heading ? ",gt_heading_deg" : "") << '\n';
  for (const RouteFrame& f : route.frames) {
    csv << core::csv_field(f.frame) << ',' << shortest(f.timestamp_s) << ','
        << core::csv_field(route_path(observations ? f.observation : f.volume, dir)) << ',';
    if (geo) {
      csv << shortest(f.crop_geo->lat_deg) << ',' << shortest(f.crop_geo->lon_deg);
    } else {
      csv << shortest(f.crop_grid->x_m) << ',' << shortest(f.crop_grid->y_m);
    }
    csv << ',' << shortest(f.odometry.forward_m) << ',' << shortest(f.odometry.left_m) << ','
        << shortest(f.odometry.yaw_deg);
    if (gps) {
      csv << ',';
      if (f.gps)
        csv << shortest(f.gps->where.lat_deg) << ',' << shortest(f.gps->where.lon_deg) << ','
            << shortest(f.gps->sigma_m);
      else
        csv << ",,";
    }
    if (truth) {
      csv << ',';
      if (f.truth)
        csv << shortest(f.truth->where.lat_deg) << ',' << shortest(f.truth->where.lon_deg);
      else
        csv << ',';
    }
    if (heading) csv << ',' << (f.truth && f.truth->heading_deg ? shortest(*f.truth->heading_deg) : std::string());
    csv << '\n';
  }
  if (!csv.flush()) throw DataError((dir / "frames.csv").string() + ": cannot write");
}

}  // namespace seqloc::io
