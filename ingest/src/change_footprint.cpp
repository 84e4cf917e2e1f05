#include "seqloc/ingest/change_footprint.hpp"

#include <algorithm>
#include <cstring>
#include <map>
#include <optional>
#include <set>
#include <string>
#include <tuple>
#include <type_traits>

#include "seqloc/raster/tile_renderer.hpp"

namespace seqloc::ingest {
namespace {

// A feature's identity (kind, OSM id, from a relation) and its whole content as bytes, so that two
// features are equal exactly when everything the renderer reads of them is.
using Identity = std::tuple<char, std::int64_t, bool>;

std::string group_bytes(osm::Group g) { return {static_cast<char>(g.channel), static_cast<char>(g.index)}; }

void append(std::string& s, double v) {
  char b[sizeof v];
  std::memcpy(b, &v, sizeof v);
  s.append(b, sizeof v);
}

std::string content(const osm::PointFeature& f) {
  std::string s = group_bytes(f.group);
  append(s, f.where.lat_deg);
  append(s, f.where.lon_deg);
  return s;
}

std::string content(const osm::LineFeature& f) {
  std::string s = group_bytes(f.group);
  s += f.highway + '\0';
  for (const auto& p : f.points) {
    append(s, p.lat_deg);
    append(s, p.lon_deg);
  }
  return s;
}

std::string content(const osm::AreaFeature& f) {
  std::string s = group_bytes(f.group);
  for (const auto& ring : f.rings) {
    s += '\x01';
    for (const auto& p : ring) {
      append(s, p.lat_deg);
      append(s, p.lon_deg);
    }
  }
  return s;
}

// Each state's features by identity: their contents (a multiset: one id may give several).
using Indexed = std::map<Identity, std::multiset<std::string>>;

template <class Feature>
Identity identity_of(const Feature& f, char kind) {
  if constexpr (std::is_same_v<Feature, osm::AreaFeature>) return {kind, f.osm_id, f.from_relation};
  return {kind, f.osm_id, false};
}

template <class Feature>
void index_features(const std::vector<Feature>& features, char kind, Indexed& out) {
  for (const auto& f : features) out[identity_of(f, kind)].insert(content(f));
}

Indexed index_of(const osm::FeatureSet& s) {
  Indexed i;
  index_features(s.points, 'n', i);
  index_features(s.lines, 'l', i);
  index_features(s.areas, 'a', i);
  return i;
}

// The identities whose contents differ between the states.
std::set<Identity> changed_identities(const Indexed& before, const Indexed& after) {
  std::set<Identity> changed;
  for (const auto& [id, c] : before) {
    const auto it = after.find(id);
    if (it == after.end() || it->second != c) changed.insert(id);
  }
  for (const auto& [id, c] : after) {
    if (!before.contains(id)) changed.insert(id);
  }
  return changed;
}

// The points of `a` that `b` does not share at its ends: after their common prefix and before their
// common suffix, with one shared point on each side (the segments joining the stretch to the rest).
// The pixels whose drawing differs lie in the box of both stretches: a line draws the rest the
// same, and an area's fill changes only between its old and new edges.
std::vector<osm::GeoPoint> stretch(const std::vector<osm::GeoPoint>& a, const std::vector<osm::GeoPoint>& b) {
  auto same = [](const osm::GeoPoint& x, const osm::GeoPoint& y) {
    return x.lat_deg == y.lat_deg && x.lon_deg == y.lon_deg;
  };
  const std::size_t n = std::min(a.size(), b.size());
  std::size_t prefix = 0, suffix = 0;
  while (prefix < n && same(a[prefix], b[prefix])) ++prefix;
  while (suffix < n - prefix && same(a[a.size() - 1 - suffix], b[b.size() - 1 - suffix])) ++suffix;
  const std::size_t from = prefix > 0 ? prefix - 1 : 0, to = std::min(a.size(), a.size() - suffix + 1);
  return from < to ? std::vector<osm::GeoPoint>(a.begin() + static_cast<std::ptrdiff_t>(from),
                                                a.begin() + static_cast<std::ptrdiff_t>(to))
                   : std::vector<osm::GeoPoint>{};
}

// A changed line or area that stays one feature of the same kind, group and rings: its changed
// stretches, as lines of its group (only their boxes matter). Nothing when it changed otherwise.
template <class Feature>
std::optional<std::vector<osm::LineFeature>> stretches(const Feature& a, const Feature& b) {
  if (!(a.group == b.group)) return std::nullopt;
  std::vector<osm::LineFeature> out;
  auto add = [&](const std::vector<osm::GeoPoint>& x, const std::vector<osm::GeoPoint>& y) {
    for (auto part : {stretch(x, y), stretch(y, x)}) {
      if (!part.empty()) out.push_back({a.group, a.osm_id, "", std::move(part)});
    }
  };
  if constexpr (std::is_same_v<Feature, osm::LineFeature>) {
    if (a.highway != b.highway) return std::nullopt;
    add(a.points, b.points);
  } else {
    if (a.rings.size() != b.rings.size()) return std::nullopt;
    for (std::size_t r = 0; r < a.rings.size(); ++r) add(a.rings[r], b.rings[r]);
  }
  return out;
}

// The features of both states under the changed identities (both states' go into one set: their
// boxes are what matters), each one-to-one change of a line or area narrowed to its changed
// stretches. Returns how many features there were.
template <class Feature>
std::size_t narrow(const std::vector<Feature>& before, const std::vector<Feature>& after, char kind,
                   const std::set<Identity>& changed, std::vector<Feature>& whole,
                   std::vector<osm::LineFeature>& parts) {
  std::map<Identity, std::pair<std::vector<const Feature*>, std::vector<const Feature*>>> both;
  std::size_t count = 0;
  for (const auto& f : before) {
    const Identity id = identity_of(f, kind);
    if (!changed.contains(id)) continue;
    both[id].first.push_back(&f);
    ++count;
  }
  for (const auto& f : after) {
    const Identity id = identity_of(f, kind);
    if (!changed.contains(id)) continue;
    both[id].second.push_back(&f);
    ++count;
  }
  for (const auto& [id, pair] : both) {
    if constexpr (!std::is_same_v<Feature, osm::PointFeature>) {
      if (pair.first.size() == 1 && pair.second.size() == 1) {
        if (auto s = stretches(*pair.first[0], *pair.second[0])) {
          parts.insert(parts.end(), std::make_move_iterator(s->begin()), std::make_move_iterator(s->end()));
          continue;
        }
      }
    }
    for (const auto* f : pair.first) whole.push_back(*f);
    for (const auto* f : pair.second) whole.push_back(*f);
  }
  return count;
}

}  // namespace

ChangeFootprint change_footprint(const raster::CacheMetadata& metadata, const osm::FeatureSet& before,
                                 const osm::FeatureSet& after) {
  const std::set<Identity> changed = changed_identities(index_of(before), index_of(after));
  // Lines and areas changed in place count by their changed stretches only.
  osm::FeatureSet moved;
  std::vector<osm::LineFeature> parts;
  ChangeFootprint footprint;
  footprint.features_changed = narrow(before.points, after.points, 'n', changed, moved.points, parts) +
                               narrow(before.lines, after.lines, 'l', changed, moved.lines, parts) +
                               narrow(before.areas, after.areas, 'a', changed, moved.areas, parts);
  moved.lines.insert(moved.lines.end(), std::make_move_iterator(parts.begin()), std::make_move_iterator(parts.end()));
  const raster::RegionFeatures pixels = raster::project_features(moved, metadata.projection());
  const auto& grid = metadata.grid;
  const std::int64_t halo = raster::TileRenderer::halo_for(metadata.max_distance_m);
  std::set<std::pair<std::int64_t, std::int64_t>> tiles;
  auto add = [&](const raster::PixelBox& box, std::int64_t margin) {
    const raster::TileSpan t = raster::tiles_meeting(grid, box, margin);
    for (std::int64_t r = t.r0; r <= t.r1; ++r)
      for (std::int64_t c = t.c0; c <= t.c1; ++c) tiles.emplace(c, r);
  };
  for (const auto& n : pixels.nodes) add({n.at.u, n.at.v, n.at.u, n.at.v}, 0);
  for (const auto& l : pixels.lines) add(l.box, l.group == osm::kRoad ? halo : 0);
  for (const auto& a : pixels.areas) add(a.box, 0);
  footprint.tiles.assign(tiles.begin(), tiles.end());
  return footprint;
}

}  // namespace seqloc::ingest
