#pragma once
// The road-prior service (docs/serve.md): every endpoint of `seqloc serve` as a function from a
// request to a response, with no sockets involved, so that routing, parameters, errors, ETags and
// limits are tested (and fuzzed) directly. server.hpp puts it behind HTTP.

#include <atomic>
#include <cstdint>
#include <filesystem>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "seqloc/raster/cache.hpp"
#include "seqloc/raster/lru_cache.hpp"
#include "seqloc/serve/map_layers.hpp"

namespace seqloc::serve {

struct Request {
  std::string method = "GET";
  std::string path;                                  ///< decoded path, without the query
  std::multimap<std::string, std::string> query;    ///< decoded parameters
  std::string if_none_match;                         ///< the If-None-Match header, if any
  std::string base_url;  ///< scheme and authority for absolute links ("http://127.0.0.1:8080"); empty: relative
};

/// Decodes a request target in origin form ("/regions/x/crop?lat=1&lon=2") into the path and the
/// query parameters: %XX escapes decoded, '+' in the query is a space, an empty parameter name
/// ignored. Throws RequestError (bad request) for a target that does not start with '/', longer
/// than kMaxTargetBytes, with a malformed escape, or with a control byte after decoding.
[[nodiscard]] Request parse_request(std::string_view method, std::string_view target);

inline constexpr std::size_t kMaxTargetBytes = 8192;

struct Response {
  int status = 200;
  std::string content_type = "application/json";
  std::shared_ptr<const std::string> body;           ///< shared with the response cache
  std::vector<std::pair<std::string, std::string>> headers;

  [[nodiscard]] const std::string& text() const;
};

struct ServiceOptions {
  LayerOptions layers;
  double max_crop_m = kDefaultMaxCropM;              ///< largest crop side
  std::size_t response_cache_bytes = 256u << 20;     ///< encoded tiles kept in memory
  std::size_t tile_lru = 256;                        ///< decoded tiles kept per region
  /// Files of the viewer page, served at `/` and `/viewer/NAME`; none when empty.
  std::filesystem::path web_root;
  int tile_max_age_s = 3600;                         ///< Cache-Control max-age of tiles and crops
  /// How often (seconds) a request looks whether its region's file was replaced (a new build
  /// renamed over it); a replaced cache is reopened and served from then on, requests under way
  /// finish on the old one. 0: on every request; negative: never.
  double reload_check_s = 1.0;
  /// Told of each reload: the region id, and an empty string or why the new file was not taken.
  std::function<void(const std::string& id, const std::string& error)> on_reload;

  /// Throws ServiceError naming the field, its value and the constraint it breaks.
  void validate() const;
};

/// A configuration that cannot be served (a missing cache, two regions of one id); names the file.
/// Data by default (the caches given); usage for an option (validate()), io for a socket that
/// cannot be bound.
class ServiceError : public Error {
 public:
  explicit ServiceError(const std::string& message, ErrorCategory category = ErrorCategory::data)
      : Error(category, message) {}
};

class Service {
 public:
  /// Opens every cache (region id = the file name without `.gpkg`); loads the viewer's files.
  /// A cache replaced on disk later (by rename, as `seqloc preprocess --overwrite` does) is picked
  /// up by the requests that follow; one that cannot be opened keeps the previous one in service.
  Service(const std::vector<std::filesystem::path>& caches, ServiceOptions options);
  ~Service();
  Service(const Service&) = delete;
  Service& operator=(const Service&) = delete;

  /// Answers one request; never throws for anything a client sends.
  [[nodiscard]] Response handle(const Request& request);

  [[nodiscard]] std::vector<std::string> region_ids() const;
  /// The cache currently served for `id` (shared: it stays valid after a reload).
  [[nodiscard]] std::shared_ptr<raster::CacheReader> region(const std::string& id);

  struct Stats {
    std::uint64_t requests = 0, cache_hits = 0;
  };
  [[nodiscard]] Stats stats() const;

 private:
  struct Region;
  struct RegionSlot;
  /// The region's current snapshot, reopened first when its file was replaced.
  std::shared_ptr<Region> current(RegionSlot& slot);
  [[nodiscard]] std::shared_ptr<Region> open_region(const std::string& id, const std::filesystem::path& path) const;
  Response route(const Request& request);
  Response tile(Region& region, std::string_view layer, std::string_view col, std::string_view file,
                const Request& request);
  /// The encoded tile under `key` from the response cache, or made by `encode`, tagged for HTTP
  /// caches (ETag, Cache-Control) and kept.
  Response cached_tile(const Region& region, const std::string& key, std::string content_type,
                       const std::function<std::shared_ptr<const std::string>()>& encode);
  Response xyz_tile(Region& region, std::string_view layer, std::string_view z, std::string_view x,
                    std::string_view file, const Request& request);
  Response crop(Region& region, const Request& request, bool sidecar_only);
  Response point(Region& region, std::string_view where);
  Response tilejson(const Region& region, const Request& request) const;
  Response wmts(const Region& region, const Request& request) const;
  Response gdal_wmts(const Region& region, std::string_view file, const Request& request) const;
  Response catalog(const Request& request);
  Response static_file(std::string_view name) const;

  ServiceOptions options_;
  std::map<std::string, std::unique_ptr<RegionSlot>> regions_;
  std::map<std::string, std::pair<std::string, std::shared_ptr<const std::string>>> web_files_;  // name -> type, body

  // Encoded tiles by request key, least recently used first out, bounded in bytes.
  mutable std::mutex cache_mutex_;
  raster::LruCache<std::string, Response> responses_;  ///< guarded by cache_mutex_
  std::atomic<std::uint64_t> requests_{0}, cache_hits_{0};  // counted without the cache's lock
};

/// A JSON error body {"error": {"status": S, "message": M}} with that status.
[[nodiscard]] Response error_response(int status, const std::string& message);

/// The HTTP status of an error, decided here once and by its category alone: 404 for not_found
/// (an unknown region, a tile or window outside the region, a crop around a point outside it), 400
/// for usage (the client's request), 500 for everything else (a damaged cache, a GDAL failure: the
/// server's fault, not the client's).
[[nodiscard]] int http_status(const std::exception& error);

}  // namespace seqloc::serve
