// The regions a service holds: opening a cache, and reopening it when its file is replaced (hot reload).
#include "seqloc/serve/service.hpp"

#include <algorithm>
#include <cmath>
#include <fstream>
#include <optional>

#include "seqloc/serve/tile_archive.hpp"
#include "service_internal.hpp"

namespace seqloc::serve {

void ServiceOptions::validate() const {
  auto fail = [](const std::string& field, const std::string& value, const char* constraint) {
    throw ServiceError("service options: " + field + " = " + value + ": " + constraint, ErrorCategory::usage);
  };
  if (!(max_crop_m > 0) || !std::isfinite(max_crop_m))
    fail("max_crop_m", std::to_string(max_crop_m), "must be finite and > 0");
  if (tile_lru < 1) fail("tile_lru", std::to_string(tile_lru), "must be >= 1");
  if (tile_max_age_s < 0) fail("tile_max_age_s", std::to_string(tile_max_age_s), "must be >= 0");
  if (std::isnan(reload_check_s)) fail("reload_check_s", "nan", "must be a number (< 0: never)");
  try {
    layers.validate();
  } catch (const RequestError& e) {
    throw ServiceError(std::string("service options: ") + e.what(), ErrorCategory::usage);
  }
}

namespace detail {

/// A region id from a file name: letters, digits, '-' and '_' only (ids appear in URLs).
std::string region_id(const std::filesystem::path& path) {
  std::string id = path.stem().string();
  for (char& c : id) {
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '-' || c == '_')) c = '_';
  }
  return id;
}

std::optional<FileIdentity> identity_of(const std::filesystem::path& path) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return std::nullopt;
  return FileIdentity{st.st_dev, st.st_ino,
                      static_cast<std::int64_t>(st.st_mtim.tv_sec) * 1'000'000'000 + st.st_mtim.tv_nsec,
                      static_cast<std::int64_t>(st.st_size)};
}

}  // namespace detail

std::shared_ptr<Service::Region> Service::open_region(const std::string& id, const std::filesystem::path& path) const {
  auto region = std::make_shared<Region>();
  region->id = id;
  // The identity first: should the file be replaced while it is being opened, the next check
  // sees a difference and opens the new one.
  region->file = detail::identity_of(path).value_or(detail::FileIdentity{});
  region->cache = std::make_shared<raster::CacheReader>(path, options_.tile_lru);
  const auto& m = region->cache->metadata();
  region->build_tag = detail::hex(detail::fnv1a(
      m.source_sha256 + "|" + m.created_utc + "|" + m.software_version + "|" + std::to_string(m.format_version) + "|" +
      SEQLOC_VERSION + "|" + detail::fixed(options_.layers.prior_sigma_m, 6) + "|" +
      std::to_string(region->file.inode) + "|" + std::to_string(region->file.mtime_ns)));
  region->bounds = region_geo_bounds(m);
  return region;
}

std::shared_ptr<Service::Region> Service::current(RegionSlot& slot) {
  std::optional<detail::FileIdentity> file;
  std::string id;
  {
    std::lock_guard lock(slot.mutex);
    if (options_.reload_check_s < 0) return slot.region;
    const auto now = std::chrono::steady_clock::now();
    if (now - slot.checked < std::chrono::duration<double>(options_.reload_check_s)) return slot.region;
    slot.checked = now;
    file = detail::identity_of(slot.path);
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

Service::Service(const std::vector<std::filesystem::path>& caches, ServiceOptions options)
    : options_(std::move(options)),
      responses_(options_.response_cache_bytes, [](const Response& r) { return r.body->size(); }) {
  options_.validate();
  if (caches.empty()) throw ServiceError("no region cache given");
  for (const auto& path : caches) {
    const std::string id = detail::region_id(path);
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
      web_files_[name] = {detail::content_type_of(ext.empty() ? ext : ext.substr(1)),
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

}  // namespace seqloc::serve
