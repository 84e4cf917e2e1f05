#include "seqloc/io/calibration_file.hpp"

#include <nlohmann/json.hpp>

#include "json_file.hpp"
#include "seqloc/core/error.hpp"

namespace seqloc::io {

std::string calibration_file_json(const CalibrationFile& c) {
  const nlohmann::ordered_json j = {{"format", "seqloc-calibration"},
                                    {"version", 1},
                                    {"temperature", c.temperature},
                                    {"blur_cells", c.blur_cells},
                                    {"blur_bins", c.blur_bins},
                                    {"floor", c.floor},
                                    {"nll", c.nll},
                                    {"uniform_nll", c.uniform_nll},
                                    {"as_given_nll", c.as_given_nll},
                                    {"frames", c.frames},
                                    {"skipped", c.skipped}};
  return j.dump(2) + "\n";
}

CalibrationFile read_calibration_file(const std::filesystem::path& path) {
  const nlohmann::json j = detail::read_json_file(path, "seqloc-calibration", 1, "calibration file");
  auto number = [&](const char* key) {
    if (!j.contains(key) || !j[key].is_number()) throw DataError(path.string() + ": '" + key + "' must be a number");
    return j[key].get<double>();
  };
  auto optional_number = [&](const char* key) { return j.contains(key) ? number(key) : 0.0; };
  auto optional_count = [&](const char* key) {
    if (!j.contains(key)) return std::size_t{0};
    if (!j[key].is_number_unsigned()) throw DataError(path.string() + ": '" + key + "' must be a count");
    return j[key].get<std::size_t>();
  };
  CalibrationFile c;
  c.temperature = number("temperature");
  c.blur_cells = number("blur_cells");
  c.blur_bins = number("blur_bins");
  c.floor = number("floor");
  c.nll = optional_number("nll");
  c.uniform_nll = optional_number("uniform_nll");
  c.as_given_nll = optional_number("as_given_nll");
  c.frames = optional_count("frames");
  c.skipped = optional_count("skipped");
  return c;
}

}  // namespace seqloc::io
