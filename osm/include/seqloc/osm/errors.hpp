#pragma once
// Errors of the osm module: problems with input data or files, never programmer errors.

#include <stdexcept>
#include <string>

namespace seqloc::osm {

/// Base of every data or I/O error raised while reading OpenStreetMap input.
class OsmError : public std::runtime_error {
 public:
  using std::runtime_error::runtime_error;
};

/// The input file cannot be opened, is truncated or is not valid OSM data.
class OsmInputError : public OsmError {
 public:
  using OsmError::OsmError;
};

}  // namespace seqloc::osm
