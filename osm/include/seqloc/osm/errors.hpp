#pragma once
// Errors of the osm module: problems with input data or files, never programmer errors.

#include <string>

#include "seqloc/core/error.hpp"

namespace seqloc::osm {

/// Base of every data or I/O error raised while reading OpenStreetMap input.
class OsmError : public Error {
 public:
  explicit OsmError(const std::string& message) : Error(ErrorCategory::data, message) {}
};

/// The input file cannot be opened, is truncated or is not valid OSM data.
class OsmInputError : public OsmError {
 public:
  explicit OsmInputError(const std::string& message) : OsmError(message) {}
};

}  // namespace seqloc::osm
