#pragma once
// The Monaco extract's region cache, built once per test binary (the serve tests' real region).

#include <filesystem>

#include "seqloc/ingest/preprocess.hpp"
#include "support/test_support.hpp"

namespace seqloc::serve::test_data {

inline std::filesystem::path monaco_cache() {
  static test::ScratchDir dir;
  static std::filesystem::path built;
  if (built.empty()) {
    ingest::PreprocessOptions options;
    options.input = test::osm_extract("monaco.osm.pbf");
    options.output = dir / "monaco.gpkg";
    options.threads = 2;
    ingest::preprocess_region(options);
    built = options.output;
  }
  return built;
}

}  // namespace seqloc::serve::test_data
