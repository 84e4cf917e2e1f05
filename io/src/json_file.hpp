#pragma once
// The JSON files io writes with a "format" and a "version" (calibration.json, the preprocess
// report): one reader of their envelope.

#include <filesystem>
#include <fstream>
#include <string>

#include <nlohmann/json.hpp>

#include "seqloc/core/error.hpp"

namespace seqloc::io::detail {

/// The object in `path`, after checking that its "format" is `format` and its "version"
/// `version`. Throws DataError naming the file, and `what` the file should have been.
inline nlohmann::json read_json_file(const std::filesystem::path& path, const std::string& format, int version,
                                     const std::string& what) {
  std::ifstream in(path);
  if (!in) throw DataError(path.string() + ": cannot read");
  nlohmann::json j;
  try {
    j = nlohmann::json::parse(in);
  } catch (const nlohmann::json::exception& e) {
    throw DataError(path.string() + ": not JSON: " + e.what());
  }
  if (!j.is_object() || j.value("format", "") != format) {
    throw DataError(path.string() + ": not a " + what + " (\"format\": \"" + format + "\" expected)");
  }
  if (j.value("version", 0) != version) {
    throw DataError(path.string() + ": " + format + " version " + j.value("version", nlohmann::json()).dump() +
                    ", this seqloc reads version " + std::to_string(version));
  }
  return j;
}

}  // namespace seqloc::io::detail
