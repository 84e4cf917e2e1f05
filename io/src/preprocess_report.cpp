#include "seqloc/io/preprocess_report.hpp"

#include <algorithm>
#include <array>
#include <type_traits>
#include <variant>
#include <vector>

#include <nlohmann/json.hpp>

#include "json_file.hpp"
#include "seqloc/core/error.hpp"
#include "seqloc/raster/grid.hpp"

namespace seqloc::io {
namespace {

using Report = PreprocessReport;
using Member = std::variant<std::int64_t Report::*, std::uint64_t Report::*, int Report::*, double Report::*>;

struct Field {
  const char* key;
  Member member;
};

// The numbers of the report in the file's order, each written and read through this one list.
// "megapixels_per_layer" (derived) is written between corridor_m and threads; the features' counts
// are written as one object after scale_error.
constexpr std::array kHead{
    Field{"tiles_wide", &Report::tiles_wide},       Field{"tiles_high", &Report::tiles_high},
    Field{"tiles_total", &Report::tiles_total},     Field{"tiles_written", &Report::tiles_written},
    Field{"tiles_resumed", &Report::tiles_resumed}, Field{"tiles_skipped", &Report::tiles_skipped},
    Field{"corridor_m", &Report::corridor_m},
};
constexpr std::array kBody{
    Field{"threads", &Report::threads},
    Field{"read_seconds", &Report::read_seconds},
    Field{"render_seconds", &Report::render_seconds},
    Field{"total_seconds", &Report::total_seconds},
    Field{"classes_cpu_seconds", &Report::classes_cpu_seconds},
    Field{"distance_cpu_seconds", &Report::distance_cpu_seconds},
    Field{"encode_cpu_seconds", &Report::encode_cpu_seconds},
    Field{"write_seconds", &Report::write_seconds},
    Field{"start_mb", &Report::start_mb},
    Field{"read_peak_mb", &Report::read_peak_mb},
    Field{"render_start_mb", &Report::render_start_mb},
    Field{"render_peak_mb", &Report::render_peak_mb},
    Field{"spilled_bytes", &Report::spilled_bytes},
    Field{"scale_error", &Report::scale_error},
};
constexpr std::array kFeatures{
    Field{"nodes", &Report::nodes},
    Field{"lines", &Report::lines},
    Field{"areas", &Report::areas},
    Field{"roads", &Report::roads},
};
constexpr std::array kTail{
    Field{"ways_missing_nodes", &Report::ways_missing_nodes},
    Field{"multipolygon_open_chains", &Report::multipolygon_open_chains},
};

template <std::size_t N>
void write_fields(nlohmann::ordered_json& j, const std::array<Field, N>& fields, const Report& r) {
  for (const Field& f : fields) std::visit([&](auto m) { j[f.key] = r.*m; }, f.member);
}

template <std::size_t N>
void read_fields(const nlohmann::json& j, const std::array<Field, N>& fields, Report& r, const std::string& where) {
  for (const Field& f : fields) {
    std::visit(
        [&](auto m) {
          using T = std::remove_reference_t<decltype(r.*m)>;
          const auto it = j.find(f.key);
          const bool ok = it != j.end() && (std::is_floating_point_v<T> ? it->is_number()
                                            : std::is_signed_v<T>       ? it->is_number_integer()
                                                                        : it->is_number_unsigned());
          if (!ok) {
            throw DataError(where + ": '" + f.key + "' must be " +
                            (std::is_floating_point_v<T> ? "a number" : "a whole number"));
          }
          r.*m = it->template get<T>();
        },
        f.member);
  }
}

}  // namespace

std::string preprocess_report_json(const PreprocessReport& r) {
  nlohmann::ordered_json j = {{"format", "seqloc-preprocess-report"}, {"version", 1}, {"output", r.output}};
  write_fields(j, kHead, r);
  j["megapixels_per_layer"] = static_cast<double>(r.tiles_total) * raster::kTilePx * raster::kTilePx / 1e6;
  write_fields(j, kBody, r);
  nlohmann::ordered_json features = nlohmann::ordered_json::object();
  write_fields(features, kFeatures, r);
  j["features"] = features;
  write_fields(j, kTail, r);
  j["bbox"] = {r.bbox.min_lon, r.bbox.min_lat, r.bbox.max_lon, r.bbox.max_lat};
  j["centre"] = {r.centre_lat, r.centre_lon};
  return j.dump(2) + "\n";
}

PreprocessReport read_preprocess_report(const std::filesystem::path& path) {
  const std::string where = path.string();
  const nlohmann::json j = detail::read_json_file(path, "seqloc-preprocess-report", 1, "preprocess report");
  PreprocessReport r;
  if (!j.contains("output") || !j["output"].is_string()) throw DataError(where + ": 'output' must be a string");
  r.output = j["output"].get<std::string>();
  read_fields(j, kHead, r, where);
  read_fields(j, kBody, r, where);
  if (!j.contains("features") || !j["features"].is_object()) throw DataError(where + ": 'features' must be an object");
  read_fields(j["features"], kFeatures, r, where + ": features");
  read_fields(j, kTail, r, where);
  auto numbers = [&](const char* key, std::size_t n) {
    const auto it = j.find(key);
    if (it == j.end() || !it->is_array() || it->size() != n ||
        !std::all_of(it->begin(), it->end(), [](const auto& x) { return x.is_number(); })) {
      throw DataError(where + ": '" + key + "' must be an array of " + std::to_string(n) + " numbers");
    }
    return it->template get<std::vector<double>>();
  };
  const auto box = numbers("bbox", 4);
  r.bbox = {box[0], box[1], box[2], box[3]};
  const auto centre = numbers("centre", 2);
  r.centre_lat = centre[0];
  r.centre_lon = centre[1];
  return r;
}

}  // namespace seqloc::io
