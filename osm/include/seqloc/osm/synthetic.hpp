#pragma once
// Synthetic OpenStreetMap data described in local metres, written with libosmium's builders.
// The sample region in samples/ and the test fixtures are made with it, so the geometry of every
// feature is known exactly (up to OSM's 1e-7 degree coordinate precision, about 1 cm).

#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "seqloc/osm/projection.hpp"

namespace seqloc::osm {

struct LocalPoint {
  double x_m = 0;  ///< east of the map's origin
  double y_m = 0;  ///< north of the map's origin
};

using Tags = std::vector<std::pair<std::string, std::string>>;

class SyntheticMap {
 public:
  /// Local metres are those of the Transverse Mercator centred on (lat0, lon0), i.e. of the
  /// region CRS of any region whose bbox is centred there.
  SyntheticMap(double lat0_deg, double lon0_deg);
  ~SyntheticMap();
  SyntheticMap(SyntheticMap&&) noexcept;
  SyntheticMap& operator=(SyntheticMap&&) noexcept;

  std::int64_t node(LocalPoint p, const Tags& tags = {});
  /// A way through new nodes at `points`; `closed` repeats the first node at the end.
  std::int64_t way(const std::vector<LocalPoint>& points, const Tags& tags, bool closed = false);
  /// A way through existing nodes (to share nodes at intersections).
  std::int64_t way_through(const std::vector<std::int64_t>& node_ids, const Tags& tags);
  /// A relation member: `type` is 'n', 'w' or 'r'; `ref` need not exist (an extract that cut it).
  struct Member {
    char type = 'w';
    std::int64_t ref = 0;
    std::string role;
  };

  /// A type=multipolygon relation of closed untagged ways.
  std::int64_t multipolygon(const std::vector<std::vector<LocalPoint>>& outers,
                            const std::vector<std::vector<LocalPoint>>& inners, Tags tags);

  /// A relation of any members; the tags are written as given (add "type" yourself).
  std::int64_t relation(std::vector<Member> members, Tags tags);

  [[nodiscard]] const RegionProjection& projection() const { return projection_; }
  [[nodiscard]] GeoPoint to_geo(LocalPoint p) const { return projection_.reverse({p.x_m, p.y_m}); }

  /// Writes the data sorted by type and id, with a header bbox around the data grown by
  /// `margin_m`; the format follows the file name (.osm.pbf, .osm, .osm.gz, .osm.bz2).
  void write(const std::filesystem::path& path, double margin_m = 0) const;

 private:
  struct Impl;
  RegionProjection projection_;
  std::unique_ptr<Impl> impl_;
};

}  // namespace seqloc::osm
