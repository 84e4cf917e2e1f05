#pragma once
// OrienterNet's tag rules (maploc/osm/parser.py), reproduced exactly (conventions.md section 2):
// element filters (ignored tags, level/layer/underground), area detection, the label built from
// key precedence ("key:value"), and the match of a label to a group with Python's re.match
// semantics (a pattern matches a prefix of the label). An element whose label matches no group of
// its own kind falls back to the other lists in OrienterNet's order; the group then decides the
// channel it is drawn into.

#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "seqloc/osm/classes.hpp"
#include "seqloc/osm/tags.hpp"

namespace seqloc::osm {

/// How an element is drawn.
enum class Geometry { point, line, area };

struct Classification {
  Geometry geometry;
  Group group;
  std::string label;  ///< OrienterNet's label, e.g. "highway:track"
};

/// parser.parse_levels: "0;1", "-1,0" ... An unparseable value gives an empty list.
[[nodiscard]] std::vector<double> parse_levels(std::string_view text);
/// parser.filter_level: false for elements above/below ground level or underground.
[[nodiscard]] bool passes_level_filter(const TagView& tags);
/// parser.is_area for a way; `closed` is "first node id == last node id".
[[nodiscard]] bool is_area(const TagView& tags, bool closed);

/// parser.parse_node / parse_way / parse_area: the label, or nullopt.
[[nodiscard]] std::optional<std::string> node_label(const TagView& tags);
[[nodiscard]] std::optional<std::string> way_label(const TagView& tags);
[[nodiscard]] std::optional<std::string> area_label(const TagView& tags);

/// parser.match_to_group over one channel's patterns.
[[nodiscard]] std::optional<Group> match_group(std::string_view label, Channel channel);

/// A tagged node, or nullopt when OrienterNet would not draw it.
[[nodiscard]] std::optional<Classification> classify_node(const TagView& tags);
/// A way: an area (closed and area-like) or a line, or nullopt.
[[nodiscard]] std::optional<Classification> classify_way(const TagView& tags, bool closed);
/// A relation: only type=multipolygon relations are areas (no level filter, as OrienterNet).
[[nodiscard]] std::optional<Classification> classify_relation(const TagView& tags);

}  // namespace seqloc::osm
