#include "seqloc/serve/service.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <chrono>
#include <charconv>
#include <cmath>
#include <cstdio>
#include <fstream>
#include <optional>
#include <sstream>

#include <nlohmann/json.hpp>

#include "seqloc/osm/classes.hpp"
#include "seqloc/serve/geotiff.hpp"

namespace seqloc::serve {

// Strings from outside (request paths, frame ids) need not be UTF-8: replaced (U+FFFD) in JSON
// output, never a type_error thrown halfway through an answer or a run.
constexpr auto kReplaceInvalidUtf8 = nlohmann::json::error_handler_t::replace;

using nlohmann::ordered_json;

const std::string& Response::text() const {
  static const std::string empty;
  return body ? *body : empty;
}

Response error_response(int status, const std::string& message) {
  Response r;
  r.status = status;
  r.body = std::make_shared<const std::string>(
      ordered_json{{"error", {{"status", status}, {"message", message}}}}.dump(-1, ' ', false, kReplaceInvalidUtf8) +
      "\n");
  r.headers.emplace_back("Cache-Control", "no-store");
  return r;
}

namespace {

Response json_response(const ordered_json& j) {
  Response r;
  r.body = std::make_shared<const std::string>(j.dump(2, ' ', false, kReplaceInvalidUtf8) + "\n");
  r.headers.emplace_back("Cache-Control", "no-cache");
  return r;
}

// FNV-1a, 64 bits: ETags need a stable fingerprint, not a cryptographic one.
std::uint64_t fnv1a(std::string_view s, std::uint64_t h = 0xcbf29ce484222325ull) {
  for (unsigned char c : s) h = (h ^ c) * 0x100000001b3ull;
  return h;
}

std::string hex(std::uint64_t v) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
  return buf;
}

std::vector<std::string_view> split_path(std::string_view path) {
  std::vector<std::string_view> parts;
  std::size_t start = 0;
  while (start < path.size()) {
    const std::size_t slash = std::min(path.find('/', start), path.size());
    if (slash > start) parts.push_back(path.substr(start, slash - start));
    start = slash + 1;
  }
  return parts;
}

int hex_digit(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

// Percent-decodes one component of a target; `what` names it in errors.
std::string decode_component(std::string_view text, bool plus_is_space, std::string_view what) {
  std::string out;
  out.reserve(text.size());
  for (std::size_t i = 0; i < text.size(); ++i) {
    char c = text[i];
    if (c == '%') {
      const int hi = i + 2 < text.size() ? hex_digit(text[i + 1]) : -1;
      const int lo = hi >= 0 ? hex_digit(text[i + 2]) : -1;
      if (lo < 0) throw RequestError(RequestError::Kind::bad_request, std::string(what) + ": malformed %-escape");
      c = static_cast<char>(hi * 16 + lo);
      i += 2;
    } else if (c == '+' && plus_is_space) {
      c = ' ';
    }
    if (static_cast<unsigned char>(c) < 0x20 || c == 0x7f) {
      throw RequestError(RequestError::Kind::bad_request, std::string(what) + ": control character in the request");
    }
    out.push_back(c);
  }
  return out;
}

bool parse_index(std::string_view s, std::int64_t& out) {
  if (s.empty() || s.size() > 9) return false;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && end == s.data() + s.size() && out >= 0;
}

bool parse_number(std::string_view s, double& out) {
  if (s.empty() || s.size() > 64) return false;
  const auto [end, ec] = std::from_chars(s.data(), s.data() + s.size(), out);
  return ec == std::errc() && end == s.data() + s.size() && std::isfinite(out);
}

const std::string* find_param(const Request& r, const std::string& name) {
  const auto [first, last] = r.query.equal_range(name);
  if (first == last) return nullptr;
  if (std::next(first) != last) throw RequestError(RequestError::Kind::bad_request, name + ": given more than once");
  return &first->second;
}

double number_param(const Request& r, const std::string& name, std::optional<double> fallback = std::nullopt) {
  const std::string* value = find_param(r, name);
  if (!value) {
    if (fallback) return *fallback;
    throw RequestError(RequestError::Kind::bad_request, name + ": missing");
  }
  double out = 0;
  if (!parse_number(*value, out)) {
    throw RequestError(RequestError::Kind::bad_request, name + ": '" + value->substr(0, 64) + "' is not a number");
  }
  return out;
}

std::string content_type_of(std::string_view ext) {
  if (ext == "png") return "image/png";
  if (ext == "tif") return "image/tiff";
  if (ext == "npy") return "application/octet-stream";
  if (ext == "json") return "application/json";
  if (ext == "html") return "text/html; charset=utf-8";
  if (ext == "js") return "text/javascript; charset=utf-8";
  if (ext == "css") return "text/css; charset=utf-8";
  if (ext == "xml") return "application/xml";
  if (ext == "svg") return "image/svg+xml";
  return "application/octet-stream";
}

std::string fixed(double v, int digits) {
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.*f", digits, v);
  return buf;
}

/// A region id from a file name: letters, digits, '-' and '_' only (ids appear in URLs).
std::string region_id(const std::filesystem::path& path) {
  std::string id = path.stem().string();
  for (char& c : id) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_')) c = '_';
  }
  return id;
}

// What identifies one version of a file: a new build renamed over the old gets another inode.
struct FileIdentity {
  dev_t device = 0;
  ino_t inode = 0;
  std::int64_t mtime_ns = 0;
  std::int64_t size = -1;
  bool operator==(const FileIdentity&) const = default;
};

std::optional<FileIdentity> identity_of(const std::filesystem::path& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return std::nullopt;
  return FileIdentity{st.st_dev, st.st_ino,
                      static_cast<std::int64_t>(st.st_mtim.tv_sec) * 1'000'000'000 + st.st_mtim.tv_nsec,
                      static_cast<std::int64_t>(st.st_size)};
}

}  // namespace

// One opened version of a region's cache; immutable once made, shared by the requests using it.
struct Service::Region {
  std::string id;
  std::shared_ptr<raster::CacheReader> cache;
  FileIdentity file;
  std::string build_tag;  ///< changes whenever the cache's content can differ (ETags, response keys)
  osm::GeoBox bounds;     ///< lon/lat bounds of the region raster
};

struct Service::RegionSlot {
  std::filesystem::path path;
  std::mutex mutex;
  std::shared_ptr<Region> region;
  std::chrono::steady_clock::time_point checked;
  std::optional<FileIdentity> refused;  ///< a replacement that could not be opened: not retried
  bool opening = false;                 ///< a request is opening a replacement
};

Request parse_request(std::string_view method, std::string_view target) {
  if (target.size() > kMaxTargetBytes) {
    throw RequestError(RequestError::Kind::bad_request,
                       "request target of " + std::to_string(target.size()) + " bytes; at most " +
                           std::to_string(kMaxTargetBytes) + " are accepted");
  }
  if (target.empty() || target.front() != '/') {
    throw RequestError(RequestError::Kind::bad_request, "request target must be a path starting with '/'");
  }
  Request request;
  request.method = std::string(method);
  const std::size_t question = target.find('?');
  request.path = decode_component(target.substr(0, question), false, "path");
  if (question == std::string_view::npos) return request;
  std::string_view query = target.substr(question + 1);
  if (const std::size_t hash = query.find('#'); hash != std::string_view::npos) query = query.substr(0, hash);
  while (!query.empty()) {
    const std::size_t amp = std::min(query.find('&'), query.size());
    const std::string_view pair = query.substr(0, amp);
    query = query.substr(std::min(amp + 1, query.size()));
    const std::size_t equals = std::min(pair.find('='), pair.size());
    std::string key = decode_component(pair.substr(0, equals), true, "query parameter name");
    if (key.empty()) continue;
    std::string value = decode_component(pair.substr(std::min(equals + 1, pair.size())), true, "query parameter value");
    request.query.emplace(std::move(key), std::move(value));
  }
  return request;
}

std::shared_ptr<Service::Region> Service::open_region(const std::string& id, const std::filesystem::path& path) const {
  auto region = std::make_shared<Region>();
  region->id = id;
  // The identity first: should the file be replaced while it is being opened, the next check
  // sees a difference and opens the new one.
  region->file = identity_of(path).value_or(FileIdentity{});
  region->cache = std::make_shared<raster::CacheReader>(path, options_.tile_lru);
  const auto& m = region->cache->metadata();
  region->build_tag = hex(fnv1a(m.source_sha256 + "|" + m.created_utc + "|" + m.software_version + "|" +
                                std::to_string(m.format_version) + "|" + SEQLOC_VERSION + "|" +
                                fixed(options_.layers.prior_sigma_m, 6) + "|" + std::to_string(region->file.inode) +
                                "|" + std::to_string(region->file.mtime_ns)));
  const auto projection = m.projection();
  const auto& g = m.grid;
  // The lon/lat extent of the raster's outline (its edges are not meridians or parallels).
  region->bounds = {180, 90, -180, -90};
  constexpr int kSamples = 16;
  for (int i = 0; i <= kSamples; ++i) {
    const double f = static_cast<double>(i) / kSamples;
    const double x = g.min_x() + f * (g.max_x() - g.min_x()), y = g.min_y() + f * (g.max_y() - g.min_y());
    for (const osm::GridPoint p : {osm::GridPoint{x, g.min_y()}, osm::GridPoint{x, g.max_y()},
                                   osm::GridPoint{g.min_x(), y}, osm::GridPoint{g.max_x(), y}}) {
      const auto q = projection.reverse(p);
      auto& b = region->bounds;
      b.min_lon = std::min(b.min_lon, q.lon_deg), b.max_lon = std::max(b.max_lon, q.lon_deg);
      b.min_lat = std::min(b.min_lat, q.lat_deg), b.max_lat = std::max(b.max_lat, q.lat_deg);
    }
  }
  return region;
}

std::shared_ptr<Service::Region> Service::current(RegionSlot& slot) {
  std::optional<FileIdentity> file;
  std::string id;
  {
    std::lock_guard lock(slot.mutex);
    if (options_.reload_check_s < 0) return slot.region;
    const auto now = std::chrono::steady_clock::now();
    if (now - slot.checked < std::chrono::duration<double>(options_.reload_check_s)) return slot.region;
    slot.checked = now;
    file = identity_of(slot.path);
    // Unchanged, gone, a replacement already refused, or another request is opening it: keep
    // serving what is open.
    if (!file || *file == slot.region->file || file == slot.refused || slot.opening) return slot.region;
    slot.opening = true;
    id = slot.region->id;
  }
  // Opened outside the lock: the other requests go on with the previous version meanwhile.
  std::shared_ptr<Region> fresh;
  std::string error;
  try {
    fresh = open_region(id, slot.path);
  } catch (const std::exception& e) {
    error = e.what();  // not a cache: the previous one stays until the file changes again
  }
  std::shared_ptr<Region> now_served;
  {
    std::lock_guard lock(slot.mutex);
    slot.opening = false;
    if (fresh) {
      slot.region = fresh;
      slot.refused.reset();
    } else {
      slot.refused = file;
    }
    now_served = slot.region;
  }
  if (options_.on_reload) options_.on_reload(id, error);
  return now_served;
}

Service::Service(const std::vector<std::filesystem::path>& caches, ServiceOptions options) : options_(std::move(options)) {
  if (caches.empty()) throw ServiceError("no region cache given");
  for (const auto& path : caches) {
    const std::string id = region_id(path);
    if (regions_.count(id)) {
      throw ServiceError(path.string() + ": a second region with the id '" + id + "'; rename one of the files");
    }
    auto slot = std::make_unique<RegionSlot>();
    slot->path = path;
    slot->region = open_region(id, path);
    slot->checked = std::chrono::steady_clock::now();
    regions_.emplace(id, std::move(slot));
  }
  if (!options_.web_root.empty()) {
    std::error_code ec;
    if (!std::filesystem::is_directory(options_.web_root, ec)) {
      throw ServiceError(options_.web_root.string() + ": the viewer's directory does not exist");
    }
    // Loaded once: the page is served from memory, never by mapping a URL onto the file system.
    for (const auto& entry : std::filesystem::recursive_directory_iterator(options_.web_root)) {
      if (!entry.is_regular_file()) continue;
      std::ifstream in(entry.path(), std::ios::binary);
      std::ostringstream bytes;
      bytes << in.rdbuf();
      const std::string name = std::filesystem::relative(entry.path(), options_.web_root).generic_string();
      const std::string ext = entry.path().extension().string();
      web_files_[name] = {content_type_of(ext.empty() ? ext : ext.substr(1)),
                          std::make_shared<const std::string>(bytes.str())};
    }
  }
}

Service::~Service() = default;

std::vector<std::string> Service::region_ids() const {
  std::vector<std::string> ids;
  for (const auto& [id, r] : regions_) ids.push_back(id);
  return ids;
}

std::shared_ptr<raster::CacheReader> Service::region(const std::string& id) { return current(*regions_.at(id))->cache; }

Service::Stats Service::stats() const { return {requests_.load(), cache_hits_.load()}; }

Response Service::handle(const Request& request) {
  ++requests_;
  if (request.method != "GET" && request.method != "HEAD") {
    Response r = error_response(405, "only GET and HEAD are served");
    r.headers.emplace_back("Allow", "GET, HEAD");
    return r;
  }
  Response response;
  try {
    response = route(request);
  } catch (const RequestError& e) {
    response = error_response(e.kind() == RequestError::Kind::not_found ? 404 : 400, e.what());
  } catch (const raster::CacheRangeError& e) {
    response = error_response(404, e.what());
  } catch (const std::exception& e) {
    // A damaged cache or a GDAL failure: the server's fault, not the client's.
    response = error_response(500, e.what());
  }
  if (!request.if_none_match.empty() && response.status == 200) {
    for (const auto& [key, value] : response.headers) {
      if (key == "ETag" && (request.if_none_match == value || request.if_none_match == "*")) {
        Response not_modified;
        not_modified.status = 304;
        not_modified.content_type.clear();
        not_modified.headers = response.headers;
        return not_modified;
      }
    }
  }
  return response;
}

Response Service::route(const Request& request) {
  const auto parts = split_path(request.path);
  for (const auto& part : parts) {
    if (part == "." || part == "..") return error_response(404, "no such resource: " + request.path);
  }
  if (parts.empty()) return static_file("index.html");
  if (parts[0] == "health" && parts.size() == 1) {
    return json_response({{"status", "ok"}, {"version", SEQLOC_VERSION}, {"regions", regions_.size()}});
  }
  if (parts[0] == "catalog" && parts.size() == 1) return catalog(request);
  if (parts[0] == "static" && parts.size() >= 2) {
    const auto offset = static_cast<std::size_t>(parts[1].data() - request.path.data());
    return static_file(std::string_view(request.path).substr(offset));
  }
  if (parts[0] != "regions") return error_response(404, "no such resource: " + request.path);
  if (parts.size() == 1) return catalog(request);
  const auto it = regions_.find(std::string(parts[1]));
  if (it == regions_.end()) {
    return error_response(404, "no region '" + std::string(parts[1]).substr(0, 100) + "' (see /catalog)");
  }
  const std::shared_ptr<Region> snapshot = current(*it->second);  // kept for the whole request
  Region& region = *snapshot;
  if (parts.size() == 2 || (parts.size() == 3 && parts[2] == "tilejson.json")) return tilejson(region, request);
  if (parts.size() == 3 && parts[2] == "wmts.xml") return wmts(region, request);
  if (parts.size() == 3 && parts[2] == "crop") return crop(region, request, false);
  if (parts.size() == 3 && parts[2] == "crop.json") return crop(region, request, true);
  if (parts.size() == 4 && parts[2] == "point") return point(region, parts[3]);
  if (parts.size() == 5) return tile(region, parts[2], parts[3], parts[4], request);
  return error_response(404, "no such resource: " + request.path.substr(0, 200));
}

Response Service::static_file(std::string_view name) const {
  const auto it = web_files_.find(std::string(name));
  if (it == web_files_.end()) {
    if (name == "index.html") {
      return error_response(404, "this server has no viewer page (start it with --web DIR); see /catalog");
    }
    return error_response(404, "no such file: " + std::string(name).substr(0, 200));
  }
  Response r;
  r.content_type = it->second.first;
  r.body = it->second.second;
  r.headers.emplace_back("Cache-Control", "no-cache");
  r.headers.emplace_back("ETag", "\"" + hex(fnv1a(*r.body)) + "\"");
  return r;
}

Response Service::tile(Region& region, std::string_view layer_name_, std::string_view col_text, std::string_view file,
                       const Request& request) {
  const auto layer = parse_layer(layer_name_);
  if (!layer) return error_response(404, "no layer '" + std::string(layer_name_).substr(0, 100) + "' (classes, road_distance, road_prior)");
  const std::size_t dot = file.rfind('.');
  const std::string_view row_text = file.substr(0, dot == std::string_view::npos ? file.size() : dot);
  const std::string_view ext = dot == std::string_view::npos ? std::string_view() : file.substr(dot + 1);
  std::int64_t col = 0, row = 0;
  if (!parse_index(col_text, col) || !parse_index(row_text, row)) {
    return error_response(400, "tile column and row must be non-negative integers: " + request.path.substr(0, 200));
  }
  if (ext != "png" && ext != "tif" && ext != "npy") {
    return error_response(404, "tile format '" + std::string(ext).substr(0, 20) + "' (png, tif or npy)");
  }
  std::string style = "data";
  if (const std::string* s = find_param(request, "style")) style = *s;
  if (style != "data" && style != "color") return error_response(400, "style: 'data' or 'color'");
  if (style == "color" && ext != "png") return error_response(400, "style=color is a PNG style");

  const std::string key = region.build_tag + "/" + region.id + "/" + layer_name(*layer) + "/" + std::to_string(col) + "/" + std::to_string(row) +
                          "." + std::string(ext) + "/" + style;
  {
    std::lock_guard lock(cache_mutex_);
    if (auto it = lru_index_.find(key); it != lru_index_.end()) {
      lru_.splice(lru_.begin(), lru_, it->second);
      ++cache_hits_;
      return it->second->second;
    }
  }
  require_tile(*region.cache, col, row);

  Response r;
  r.content_type = content_type_of(ext);
  if (ext == "png" && style == "data" && *layer != MapLayer::road_prior) {
    // The stored blob is already this PNG: no decoding, no encoding.
    const auto blob = region.cache->tile_blob(*layer == MapLayer::classes ? raster::Layer::classes : raster::Layer::road_distance,
                                              col, row);
    r.body = std::make_shared<const std::string>(blob.begin(), blob.end());
  } else {
    const MapBlock block = read_tile(*region.cache, *layer, col, row, options_.layers);
    if (ext == "npy") {
      r.body = std::make_shared<const std::string>(encode_npy(block));
    } else if (ext == "tif") {
      r.body = std::make_shared<const std::string>(encode_geotiff(block, region.cache->metadata().projection()));
    } else {
      const auto png = style == "color" ? encode_styled_png(block) : encode_data_png(block);
      r.body = std::make_shared<const std::string>(png.begin(), png.end());
    }
  }
  r.headers.emplace_back("ETag", "\"" + region.build_tag + "-" + hex(fnv1a(key)) + "\"");
  r.headers.emplace_back("Cache-Control", "public, max-age=" + std::to_string(options_.tile_max_age_s));

  std::lock_guard lock(cache_mutex_);
  if (lru_index_.count(key) == 0 && r.body->size() <= options_.response_cache_bytes / 8) {
    lru_.emplace_front(key, r);
    lru_index_[key] = lru_.begin();
    lru_bytes_ += r.body->size();
    while (lru_bytes_ > options_.response_cache_bytes && !lru_.empty()) {
      lru_bytes_ -= lru_.back().second.body->size();
      lru_index_.erase(lru_.back().first);
      lru_.pop_back();
    }
  }
  return r;
}

Response Service::crop(Region& region, const Request& request, bool sidecar_only) {
  const double lat = number_param(request, "lat");
  const double lon = number_param(request, "lon");
  const double size_m = number_param(request, "size_m", 128.0);
  const std::string* layers_text = find_param(request, "layers");
  const auto layers = parse_layer_list(layers_text ? *layers_text : "classes,road_distance,road_prior");
  const std::string* format_text = find_param(request, "format");
  const std::string format = format_text ? *format_text : "npy";
  if (format != "npy" && format != "tif" && format != "png") {
    throw RequestError(RequestError::Kind::bad_request, "format: '" + format.substr(0, 20) + "' (npy, tif or png)");
  }
  if (format == "png" && layers.size() != 1) {
    throw RequestError(RequestError::Kind::bad_request, "format=png holds one layer; ask for one, or use npy or tif");
  }
  // A sidecar describes the crop without reading it.
  const MapBlock block = [&] {
    if (!sidecar_only) return read_crop(*region.cache, lat, lon, size_m, layers, options_.layers, options_.max_crop_m);
    const CropWindow w = locate_crop(*region.cache, lat, lon, size_m, options_.max_crop_m);
    return describe_block(*region.cache, w.u0, w.v0, w.size, w.size, layers);
  }();
  const auto& m = region.cache->metadata();
  std::string canonical;
  for (const auto& [k, v] : request.query) canonical.append(k).append("=").append(v).append("&");
  const std::string etag = "\"" + region.build_tag + "-" + hex(fnv1a(canonical + (sidecar_only ? "json" : ""))) + "\"";
  Response r;
  if (sidecar_only) {
    double gamma = 0;
    const osm::GeoPoint centre = m.projection().reverse({block.centre_x_m(), block.centre_y_m()}, gamma);
    ordered_json bands = ordered_json::array();
    for (const auto& b : block.bands) bands.push_back(b.name);
    const bool u8 = block.all_uint8();
    const std::string dtype = format == "png" ? (block.layers[0] == MapLayer::classes ? "uint8" : "uint16")
                                              : (u8 ? "uint8" : "float32");
    r = json_response({
        {"region", region.id},
        {"crs", "region"},
        {"crs_wkt", m.projection().wkt()},
        {"crs_proj", m.projection().proj_string()},
        {"crop_x", block.centre_x_m()},
        {"crop_y", block.centre_y_m()},
        {"crop_lat", centre.lat_deg},
        {"crop_lon", centre.lon_deg},
        {"meridian_convergence_deg", gamma},
        {"cell_m", raster::kCellM},
        {"width", block.width},
        {"height", block.height},
        {"west_m", block.west_m},
        {"north_m", block.north_m},
        {"geotransform", {block.west_m, raster::kCellM, 0, block.north_m, 0, -raster::kCellM}},
        {"bands", bands},
        {"dtype", dtype},
        {"outside_cells", block.outside_cells},
        {"road_distance_max_m", m.max_distance_m},
        {"road_prior_sigma_m", options_.layers.prior_sigma_m},
    });
  } else {
    std::string band_names;
    for (const auto& b : block.bands) band_names += (band_names.empty() ? "" : ",") + b.name;
    r.content_type = content_type_of(format);
    if (format == "npy") {
      r.body = std::make_shared<const std::string>(encode_npy(block));
    } else if (format == "tif") {
      r.body = std::make_shared<const std::string>(encode_geotiff(block, m.projection()));
    } else {
      const auto png = encode_data_png(block);
      r.body = std::make_shared<const std::string>(png.begin(), png.end());
    }
    r.headers.emplace_back("Cache-Control", "public, max-age=" + std::to_string(options_.tile_max_age_s));
    r.headers.emplace_back("X-Seqloc-Region", region.id);
    r.headers.emplace_back("X-Seqloc-Crop-X", fixed(block.centre_x_m(), 3));
    r.headers.emplace_back("X-Seqloc-Crop-Y", fixed(block.centre_y_m(), 3));
    r.headers.emplace_back("X-Seqloc-Cell-M", fixed(raster::kCellM, 3));
    r.headers.emplace_back("X-Seqloc-Shape", std::to_string(block.height) + "," + std::to_string(block.width) + "," +
                                                 std::to_string(block.bands.size()));
    r.headers.emplace_back("X-Seqloc-Bands", band_names);
    r.headers.emplace_back("X-Seqloc-Geotransform", fixed(block.west_m, 3) + ",0.5,0," + fixed(block.north_m, 3) + ",0,-0.5");
    r.headers.emplace_back("X-Seqloc-Crs", m.projection().proj_string());
    r.headers.emplace_back("X-Seqloc-Outside-Cells", std::to_string(block.outside_cells));
  }
  r.headers.emplace_back("ETag", etag);
  return r;
}

Response Service::point(Region& region, std::string_view where) {
  const std::size_t comma = where.find(',');
  double lon = 0, lat = 0;
  if (comma == std::string_view::npos || !parse_number(where.substr(0, comma), lon) ||
      !parse_number(where.substr(comma + 1), lat) || std::abs(lat) > 90 || std::abs(lon) > 180) {
    throw RequestError(RequestError::Kind::bad_request, "point: expected /point/LON,LAT in degrees");
  }
  const auto& m = region.cache->metadata();
  const auto& g = m.grid;
  const auto p = m.projection().forward({lat, lon});
  const double u = g.region_u(p.x_m), v = g.region_v(p.y_m);
  const auto cu = static_cast<std::int64_t>(std::floor(u + 0.5)), cv = static_cast<std::int64_t>(std::floor(v + 0.5));
  if (!(u > -0.5 && v > -0.5 && cu < g.width_px() && cv < g.height_px())) {
    throw RequestError(RequestError::Kind::not_found,
                       "the point (" + fixed(lon, 7) + ", " + fixed(lat, 7) + ") is outside region '" + region.id + "'");
  }
  const CellValues values = read_cell(*region.cache, cu, cv, options_.layers);
  ordered_json classes = ordered_json::object();
  for (int c = 0; c < osm::kChannelCount; ++c) {
    const auto channel = static_cast<osm::Channel>(c);
    const int code = values.classes[c];
    const auto names = osm::group_names(channel);
    classes[std::string(osm::channel_name(channel))] = {
        {"code", code},
        {"name", code == 0 ? "background" : (static_cast<std::size_t>(code) <= names.size() ? std::string(names[static_cast<std::size_t>(code - 1)]) : "unknown")}};
  }
  return json_response({{"region", region.id},
                        {"lon", lon},
                        {"lat", lat},
                        {"x", p.x_m},
                        {"y", p.y_m},
                        {"cell", {cu, cv}},
                        {"classes", classes},
                        {"road_distance_m", values.road_distance_m},
                        {"road_prior", values.road_prior},
                        {"road_prior_sigma_m", options_.layers.prior_sigma_m}});
}

Response Service::catalog(const Request& request) {
  ordered_json regions = ordered_json::array();
  for (const auto& [id, slot] : regions_) {
    const auto region = current(*slot);
    const auto& m = region->cache->metadata();
    regions.push_back({{"id", id},
                       {"source_file", m.source_file},
                       {"source_sha256", m.source_sha256},
                       {"created_utc", m.created_utc},
                       {"bounds", {region->bounds.min_lon, region->bounds.min_lat, region->bounds.max_lon, region->bounds.max_lat}},
                       {"center", {m.centre_lon, m.centre_lat}},
                       {"layers", {"classes", "road_distance", "road_prior"}},
                       {"tiles", {{"columns", m.grid.tiles_wide()}, {"rows", m.grid.tiles_high()}}},
                       {"tilejson", request.base_url + "/regions/" + id + "/tilejson.json"},
                       {"wmts", request.base_url + "/regions/" + id + "/wmts.xml"}});
  }
  return json_response({{"regions", regions}, {"attribution", "Map data (c) OpenStreetMap contributors, ODbL 1.0"}});
}

Response Service::tilejson(const Region& region, const Request& request) const {
  const auto& m = region.cache->metadata();
  const auto& g = m.grid;
  const std::string base = request.base_url + "/regions/" + region.id;
  ordered_json layers = ordered_json::object();
  for (MapLayer layer : kAllLayers) {
    const std::string name = layer_name(layer);
    std::string tiles = base;
    tiles.append("/").append(name).append("/{x}/{y}.png");
    layers[name] = {{"tiles", {tiles}},
                    {"formats", {"png", "tif", "npy"}},
                    {"styles", {"data", "color"}}};
  }
  return json_response(
      {{"tilejson", "3.0.0"},
       {"name", region.id},
       {"description", "seqloc region cache of " + m.source_file + " (tiles in the region's own CRS, not Web Mercator)"},
       {"attribution", "Map data (c) OpenStreetMap contributors, ODbL 1.0"},
       {"scheme", "xyz"},
       {"tiles", {base + "/classes/{x}/{y}.png?style=color"}},
       {"minzoom", 0},
       {"maxzoom", 0},
       {"bounds", {region.bounds.min_lon, region.bounds.min_lat, region.bounds.max_lon, region.bounds.max_lat}},
       {"center", {m.centre_lon, m.centre_lat, 0}},
       {"crs", {{"wkt", m.projection().wkt()}, {"proj", m.projection().proj_string()}}},
       {"tile_matrix",
        {{"tile_size", raster::kTilePx},
         {"cell_m", raster::kCellM},
         {"top_left", {g.min_x(), g.max_y()}},
         {"extent", {g.min_x(), g.min_y(), g.max_x(), g.max_y()}},
         {"columns", g.tiles_wide()},
         {"rows", g.tiles_high()}}},
       {"layers", layers},
       {"road_distance_max_m", m.max_distance_m},
       {"road_prior_sigma_m", options_.layers.prior_sigma_m},
       {"crop", base + "/crop?lat={lat}&lon={lon}&size_m=128&layers=classes,road_distance,road_prior&format=npy"},
       {"point", base + "/point/{lon},{lat}"}});
}

Response Service::wmts(const Region& region, const Request& request) const {
  const auto& m = region.cache->metadata();
  const auto& g = m.grid;
  const std::string base = request.base_url + "/regions/" + region.id;
  const std::string matrix_set = "seqloc-" + region.id;
  // Scale denominator of 0.5 m cells at the standard 0.28 mm rendering pixel (WMTS 1.0.0, 6.1).
  const double scale = raster::kCellM / 0.00028;
  std::ostringstream x;
  x.precision(17);
  x << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
    << "<Capabilities xmlns=\"http://www.opengis.net/wmts/1.0\" xmlns:ows=\"http://www.opengis.net/ows/1.1\" "
       "xmlns:xlink=\"http://www.w3.org/1999/xlink\" version=\"1.0.0\">\n"
    << "  <ows:ServiceIdentification><ows:Title>seqloc " << region.id
    << "</ows:Title><ows:ServiceType>OGC WMTS</ows:ServiceType><ows:ServiceTypeVersion>1.0.0</ows:ServiceTypeVersion>"
       "<ows:AccessConstraints>Map data (c) OpenStreetMap contributors, ODbL 1.0</ows:AccessConstraints>"
       "</ows:ServiceIdentification>\n"
    << "  <Contents>\n";
  for (MapLayer layer : kAllLayers) {
    const std::string name = layer_name(layer);
    x << "    <Layer><ows:Title>" << name << "</ows:Title><ows:Identifier>" << name << "</ows:Identifier>"
      << "<ows:WGS84BoundingBox><ows:LowerCorner>" << region.bounds.min_lon << " " << region.bounds.min_lat
      << "</ows:LowerCorner><ows:UpperCorner>" << region.bounds.max_lon << " " << region.bounds.max_lat
      << "</ows:UpperCorner></ows:WGS84BoundingBox>"
      << R"(<Style isDefault="true"><ows:Identifier>data</ows:Identifier></Style>)"
      << "<Style><ows:Identifier>color</ows:Identifier></Style>"
      << "<Format>image/png</Format>"
      << "<TileMatrixSetLink><TileMatrixSet>" << matrix_set << "</TileMatrixSet></TileMatrixSetLink>"
      << R"(<ResourceURL format="image/png" resourceType="tile" template=")" << base << "/" << name
      << "/{TileCol}/{TileRow}.png?style={Style}\"/></Layer>\n";
  }
  x << "    <TileMatrixSet><ows:Identifier>" << matrix_set << "</ows:Identifier>"
    << "<ows:SupportedCRS>" << m.projection().proj_string() << "</ows:SupportedCRS>"
    << "<TileMatrix><ows:Identifier>0</ows:Identifier><ScaleDenominator>" << scale << "</ScaleDenominator>"
    << "<TopLeftCorner>" << g.min_x() << " " << g.max_y() << "</TopLeftCorner>"
    << "<TileWidth>" << raster::kTilePx << "</TileWidth><TileHeight>" << raster::kTilePx << "</TileHeight>"
    << "<MatrixWidth>" << g.tiles_wide() << "</MatrixWidth><MatrixHeight>" << g.tiles_high() << "</MatrixHeight>"
    << "</TileMatrix></TileMatrixSet>\n"
    << "  </Contents>\n</Capabilities>\n";
  Response r;
  r.content_type = "application/xml";
  r.body = std::make_shared<const std::string>(x.str());
  r.headers.emplace_back("Cache-Control", "no-cache");
  return r;
}

}  // namespace seqloc::serve
