// The tile service: routing requests to the endpoints, static files, errors.
#include "seqloc/serve/service.hpp"

#include <cstdio>

#include <nlohmann/json.hpp>

#include "service_internal.hpp"

namespace seqloc::serve {

namespace detail {

Response json_response(const ordered_json& j) {
  Response r;
  r.body = std::make_shared<const std::string>(j.dump(2, ' ', false, kReplaceInvalidUtf8) + "\n");
  r.headers.emplace_back("Cache-Control", "no-cache");
  return r;
}

Response xml_response(std::string xml) {
  Response r;
  r.content_type = "application/xml";
  r.body = std::make_shared<const std::string>(std::move(xml));
  r.headers.emplace_back("Cache-Control", "no-cache");
  return r;
}

std::optional<std::string_view> strip_suffix(std::string_view text, std::string_view suffix) {
  if (text.size() <= suffix.size() || text.substr(text.size() - suffix.size()) != suffix) return std::nullopt;
  return text.substr(0, text.size() - suffix.size());
}

// FNV-1a, 64 bits: ETags need a stable fingerprint, not a cryptographic one.
std::uint64_t fnv1a(std::string_view s, std::uint64_t h) {
  for (unsigned char c : s) h = (h ^ c) * 0x100000001b3ull;
  return h;
}

std::string hex(std::uint64_t v) {
  char buf[17];
  std::snprintf(buf, sizeof buf, "%016llx", static_cast<unsigned long long>(v));
  return buf;
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

}  // namespace detail

const std::string& Response::text() const {
  static const std::string empty;
  return body ? *body : empty;
}

Response error_response(int status, const std::string& message) {
  Response r;
  r.status = status;
  r.body = std::make_shared<const std::string>(
      ordered_json{{"error", {{"status", status}, {"message", message}}}}.dump(-1, ' ', false, detail::kReplaceInvalidUtf8) +
      "\n");
  r.headers.emplace_back("Cache-Control", "no-store");
  return r;
}

int http_status(const std::exception& error) {
  switch (category_of(error)) {
    case ErrorCategory::not_found:
      return 404;
    case ErrorCategory::usage:
      return 400;
    case ErrorCategory::data:
    case ErrorCategory::io:
    case ErrorCategory::internal:
      break;
  }
  return 500;  // the server's own data, files or code
}

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
  } catch (const std::exception& e) {
    response = error_response(http_status(e), e.what());
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
  const auto parts = detail::split_path(request.path);
  for (const auto& part : parts) {
    if (part == "." || part == "..") return error_response(404, "no such resource: " + request.path);
  }
  if (parts.empty()) return static_file("index.html");
  if (parts[0] == "health" && parts.size() == 1) {
    return detail::json_response({{"status", "ok"}, {"version", SEQLOC_VERSION}, {"regions", regions_.size()}});
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
  if (parts.size() == 4 && parts[2] == "wmts") return gdal_wmts(region, parts[3], request);
  if (parts.size() == 3 && parts[2] == "crop") return crop(region, request, false);
  if (parts.size() == 3 && parts[2] == "crop.json") return crop(region, request, true);
  if (parts.size() == 4 && parts[2] == "point") return point(region, parts[3]);
  if (parts.size() == 5) return tile(region, parts[2], parts[3], parts[4], request);
  if (parts.size() == 7 && parts[2] == "xyz") return xyz_tile(region, parts[3], parts[4], parts[5], parts[6], request);
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
  r.headers.emplace_back("ETag", "\"" + detail::hex(detail::fnv1a(*r.body)) + "\"");
  return r;
}

}  // namespace seqloc::serve
