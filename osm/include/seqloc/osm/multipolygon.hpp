#pragma once
// Multipolygon relations assembled the way OrienterNet's MapArea.from_relation does
// (conventions.md section 2), not the way a strict assembler does: members with role "outer" or
// "inner" that are present in the input, open member ways glued end to end into rings, and a
// relation with missing members still drawn from the rings that close. The fill is even-odd over
// all rings, so which ring is outer does not change a pixel.

#include <cstddef>
#include <cstdint>
#include <optional>
#include <vector>

#include "seqloc/osm/projection.hpp"

namespace seqloc::osm {

/// A node of a way: its id (rings are glued by id) and its location, if the input has it.
struct WayNode {
  std::int64_t id = 0;
  std::optional<GeoPoint> where;
};
using NodeChain = std::vector<WayNode>;

struct GluedRings {
  std::vector<NodeChain> rings;  ///< closed: the first and last node are the same node
  std::size_t open_chains = 0;   ///< chains that stayed open (a member missing from the input)
};

/// OrienterNet's glue(): a closed way is a ring as it is; an open way is joined, end to end and
/// reversed where needed, to the next open way (in member order) sharing an endpoint, until the
/// chain closes or nothing joins it. Ways of fewer than two nodes are ignored. Deterministic
/// where OrienterNet's set order is not (a node shared by more than two chain ends).
[[nodiscard]] GluedRings glue_rings(std::vector<NodeChain> ways);

/// A relation's members as far as the assembler cares: way members of role outer or inner.
struct RingMember {
  std::int64_t way_id = 0;
  bool outer = true;
};

/// The rings a relation draws: glued outers and inners that close, outers first, as located
/// points (nodes the input lacks are skipped; a ring keeps at least three located points).
/// `find_way(id)` returns the way's nodes, or nullptr when the input does not hold it. Empty
/// when no outer member is present (OrienterNet draws nothing then).
template <class FindWay>
std::vector<std::vector<GeoPoint>> assemble_rings(const std::vector<RingMember>& members, FindWay&& find_way,
                                                  std::size_t* open_chains = nullptr);

// ---------------------------------------------------------------------------------------------

/// The located points of a closed chain, or empty when fewer than three remain.
[[nodiscard]] std::vector<GeoPoint> ring_points(const NodeChain& ring);

template <class FindWay>
std::vector<std::vector<GeoPoint>> assemble_rings(const std::vector<RingMember>& members, FindWay&& find_way,
                                                  std::size_t* open_chains) {
  std::vector<NodeChain> outers, inners;
  for (const auto& member : members) {
    const NodeChain* way = find_way(member.way_id);
    if (way == nullptr) continue;
    (member.outer ? outers : inners).push_back(*way);
  }
  std::vector<std::vector<GeoPoint>> rings;
  if (outers.empty()) return rings;
  for (auto* group : {&outers, &inners}) {
    const auto glued = glue_rings(std::move(*group));
    if (open_chains != nullptr) *open_chains += glued.open_chains;
    for (const auto& ring : glued.rings) {
      auto points = ring_points(ring);
      if (!points.empty()) rings.push_back(std::move(points));
    }
  }
  return rings;
}

}  // namespace seqloc::osm
