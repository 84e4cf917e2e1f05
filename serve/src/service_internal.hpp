#pragma once
// What the parts of the service share (service.cpp: routing, static files; request.cpp: decoding
// request targets and parameters; regions.cpp: opening regions and their hot reload;
// endpoints.cpp: tiles, crops, points, TileJSON, WMTS, the catalog). Private to serve.

#include <sys/stat.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include <nlohmann/json.hpp>

#include "seqloc/serve/service.hpp"

namespace seqloc::serve {

using nlohmann::ordered_json;

namespace detail {

// Strings from outside (request paths, frame ids) need not be UTF-8: replaced (U+FFFD) in JSON
// output, never a type_error thrown halfway through an answer or a run.
inline constexpr auto kReplaceInvalidUtf8 = nlohmann::json::error_handler_t::replace;

// What identifies one version of a file: a new build renamed over the old gets another inode.
struct FileIdentity {
  dev_t device = 0;
  ino_t inode = 0;
  std::int64_t mtime_ns = 0;
  std::int64_t size = -1;
  bool operator==(const FileIdentity&) const = default;
};

Response json_response(const ordered_json& j);
/// An XML document (capabilities, service descriptions), not cached by clients.
Response xml_response(std::string xml);
/// `text` without `suffix`, when it ends with it and has more before it.
std::optional<std::string_view> strip_suffix(std::string_view text, std::string_view suffix);
std::string hex(std::uint64_t v);
std::vector<std::string_view> split_path(std::string_view path);
/// Percent-decodes one component of a target; `what` names it in errors.
std::string decode_component(std::string_view text, bool plus_is_space, std::string_view what);
bool parse_index(std::string_view s, std::int64_t& out);
bool parse_number(std::string_view s, double& out);
const std::string* find_param(const Request& r, const std::string& name);
std::string content_type_of(std::string_view ext);
std::string fixed(double v, int digits);
//// A region id from a file name: letters, digits, '-' and '_' only (ids appear in URLs).
std::string region_id(const std::filesystem::path& path);
std::optional<FileIdentity> identity_of(const std::filesystem::path& path);
std::uint64_t fnv1a(std::string_view s, std::uint64_t h = 0xcbf29ce484222325ull);
double number_param(const Request& r, const std::string& name, std::optional<double> fallback = std::nullopt);

}  // namespace detail

// One opened version of a region's cache; immutable once made, shared by the requests using it.
struct Service::Region {
  std::string id;
  std::shared_ptr<raster::CacheReader> cache;
  detail::FileIdentity file;
  std::string build_tag;  ///< changes whenever the cache's content can differ (ETags, response keys)
  osm::GeoBox bounds;     ///< lon/lat bounds of the region raster
};

struct Service::RegionSlot {
  std::filesystem::path path;
  std::mutex mutex;
  std::shared_ptr<Region> region;
  std::chrono::steady_clock::time_point checked;
  std::optional<detail::FileIdentity> refused;  ///< a replacement that could not be opened: not retried
  bool opening = false;                 ///< a request is opening a replacement
};

}  // namespace seqloc::serve
