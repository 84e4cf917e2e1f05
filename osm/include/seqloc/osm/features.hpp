#pragma once
// The classified OSM features of an input file, in geographic coordinates.

#include <cstdint>
#include <optional>
#include <string>
#include <vector>

#include "seqloc/osm/classes.hpp"
#include "seqloc/osm/projection.hpp"

namespace seqloc::osm {

struct GeoBox {
  double min_lon = 0, min_lat = 0, max_lon = 0, max_lat = 0;

  [[nodiscard]] bool valid() const { return min_lon <= max_lon && min_lat <= max_lat; }
  [[nodiscard]] bool intersects(const GeoBox& o) const {
    return min_lon <= o.max_lon && o.min_lon <= max_lon && min_lat <= o.max_lat && o.min_lat <= max_lat;
  }
  [[nodiscard]] GeoPoint centre() const { return {(min_lat + max_lat) / 2, (min_lon + max_lon) / 2}; }
  void extend(GeoPoint p) {
    if (!valid()) {
      *this = {p.lon_deg, p.lat_deg, p.lon_deg, p.lat_deg};
      return;
    }
    if (p.lon_deg < min_lon) min_lon = p.lon_deg;
    if (p.lon_deg > max_lon) max_lon = p.lon_deg;
    if (p.lat_deg < min_lat) min_lat = p.lat_deg;
    if (p.lat_deg > max_lat) max_lat = p.lat_deg;
  }
  /// An empty box (valid() is false) that extend() initialises.
  static GeoBox empty() { return {1, 1, 0, 0}; }
};

struct PointFeature {
  Group group{};
  std::int64_t osm_id = 0;
  GeoPoint where;
};

struct LineFeature {
  Group group;
  std::int64_t osm_id;
  std::string highway;  ///< the highway tag (kept for the cache's roads table), may be empty
  std::vector<GeoPoint> points;
};

/// A filled area: the union under the even-odd rule of its rings (outers and inners alike).
struct AreaFeature {
  Group group;
  std::int64_t osm_id;  ///< way id, or relation id for multipolygons
  bool from_relation;
  std::vector<std::vector<GeoPoint>> rings;
};

struct FeatureSet {
  std::vector<PointFeature> points;
  std::vector<LineFeature> lines;
  std::vector<AreaFeature> areas;

  std::optional<GeoBox> header_box;  ///< the bbox the file's header declares, if any
  GeoBox data_box = GeoBox::empty();  ///< the bbox of every node location in the file
  std::string replication_timestamp;  ///< from the header, empty if absent
  std::uint64_t ways_missing_nodes = 0;  ///< ways that referenced nodes absent from the file
  std::size_t multipolygon_open_chains = 0;  ///< member chains of relations that did not close
};

}  // namespace seqloc::osm
