// Request targets and parameters: strict percent-decoding and number parsing.
#include "seqloc/serve/service.hpp"

#include <algorithm>
#include <charconv>
#include <cmath>
#include <optional>

#include "service_internal.hpp"

namespace seqloc::serve {
namespace {

int hex_digit(char c) {
  if (c >= '0' && c <= '9') return c - '0';
  if (c >= 'a' && c <= 'f') return c - 'a' + 10;
  if (c >= 'A' && c <= 'F') return c - 'A' + 10;
  return -1;
}

}  // namespace

namespace detail {

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

double number_param(const Request& r, const std::string& name, std::optional<double> fallback) {
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

}  // namespace detail

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
  request.path = detail::decode_component(target.substr(0, question), false, "path");
  if (question == std::string_view::npos) return request;
  std::string_view query = target.substr(question + 1);
  if (const std::size_t hash = query.find('#'); hash != std::string_view::npos) query = query.substr(0, hash);
  while (!query.empty()) {
    const std::size_t amp = std::min(query.find('&'), query.size());
    const std::string_view pair = query.substr(0, amp);
    query = query.substr(std::min(amp + 1, query.size()));
    const std::size_t equals = std::min(pair.find('='), pair.size());
    std::string key = detail::decode_component(pair.substr(0, equals), true, "query parameter name");
    if (key.empty()) continue;
    std::string value = detail::decode_component(pair.substr(std::min(equals + 1, pair.size())), true, "query parameter value");
    request.query.emplace(std::move(key), std::move(value));
  }
  return request;
}

}  // namespace seqloc::serve
