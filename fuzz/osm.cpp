// Fuzz target: OSM input through libosmium on an in-memory buffer, then our classification
// (osm/reader.hpp). The first byte picks the format (PBF, XML, OPL), the rest is the data.
#include <cstdint>
#include <span>

#include "seqloc/osm/reader.hpp"

extern "C" int LLVMFuzzerTestOneInput(const std::uint8_t* data, std::size_t size) {
  if (size < 2) return 0;
  static const char* const formats[] = {"pbf", "xml", "opl"};
  const char* format = formats[data[0] % 3];
  try {
    const auto features = seqloc::osm::read_osm_buffer(
        std::span(reinterpret_cast<const char*>(data + 1), size - 1), format, "fuzz input");
    for (const auto& line : features.lines) {
      if (line.points.size() < 2) std::abort();  // a line feature has at least two points
    }
  } catch (const seqloc::osm::OsmError&) {
  }
  return 0;
}
