// Multipolygon relations assembled as OrienterNet's MapArea.from_relation does (conventions.md
// section 2): gluing of open members in every orientation, relations with members missing from
// the extract, roles other than outer/inner, and the same read from a file made with libosmium.

#include <algorithm>
#include <map>

#include <gtest/gtest.h>

#include "seqloc/osm/multipolygon.hpp"
#include "seqloc/osm/reader.hpp"
#include "seqloc/osm/synthetic.hpp"
#include "support/test_support.hpp"

namespace seqloc::osm {
namespace {

NodeChain chain(std::initializer_list<std::int64_t> ids) {
  NodeChain c;
  for (auto id : ids) c.push_back({id, GeoPoint{static_cast<double>(id), 0.0}});
  return c;
}

std::vector<std::int64_t> ids_of(const NodeChain& c) {
  std::vector<std::int64_t> ids;
  for (const auto& n : c) ids.push_back(n.id);
  return ids;
}

// The ring as a cycle, independent of where it starts and which way it runs.
std::vector<std::int64_t> canonical_cycle(const NodeChain& ring) {
  std::vector<std::int64_t> ids = ids_of(ring);
  ids.pop_back();  // closed: the last node repeats the first
  auto best = ids;
  for (int direction = 0; direction < 2; ++direction) {
    for (std::size_t shift = 0; shift < ids.size(); ++shift) {
      std::vector<std::int64_t> rotated(ids.begin() + static_cast<std::ptrdiff_t>(shift), ids.end());
      rotated.insert(rotated.end(), ids.begin(), ids.begin() + static_cast<std::ptrdiff_t>(shift));
      best = std::min(best, rotated);
    }
    std::reverse(ids.begin(), ids.end());
  }
  return best;
}

TEST(Glue, OpenMembersJoinInEveryOrientation) {
  // A ring 1-2-3-4-5-6-1 cut into three ways, the second given backwards, listed out of order.
  const auto glued = glue_rings({chain({3, 4, 5}), chain({1, 2, 3}), chain({1, 6, 5})});
  ASSERT_EQ(glued.rings.size(), 1u);
  EXPECT_EQ(glued.open_chains, 0u);
  EXPECT_EQ(canonical_cycle(glued.rings[0]), (std::vector<std::int64_t>{1, 2, 3, 4, 5, 6}));
  EXPECT_EQ(glued.rings[0].front().id, glued.rings[0].back().id);
  // Each of the four endpoint pairings of try_to_glue on its own.
  for (const auto& [a, b] : std::vector<std::pair<NodeChain, NodeChain>>{
           {chain({1, 2, 3}), chain({3, 4, 1})},   // end to start
           {chain({1, 2, 3}), chain({1, 4, 3})},   // end to end, and start to start
           {chain({3, 4, 1}), chain({1, 2, 3})},   // start to end
           {chain({2, 3, 1}), chain({2, 4, 1})}}) {  // start to start
    const auto g = glue_rings({a, b});
    ASSERT_EQ(g.rings.size(), 1u);
    EXPECT_EQ(g.rings[0].size(), 5u);
    EXPECT_EQ(g.rings[0].front().id, g.rings[0].back().id);
  }
}

TEST(Glue, AMissingMemberLeavesAnOpenChainAndClosedRingsStayAsTheyAre) {
  // Ring 1..6 with its way 5-6-1 missing: two ways glue into 1-2-3-4-5, which stays open.
  // Two closed inner rings touching at node 20 stay two rings (OrienterNet keeps them apart).
  const auto glued = glue_rings({chain({1, 2, 3}), chain({3, 4, 5}), chain({20, 21, 22, 20}), chain({20, 23, 24, 20})});
  EXPECT_EQ(glued.rings.size(), 2u);
  EXPECT_EQ(glued.open_chains, 1u);
  for (const auto& ring : glued.rings) EXPECT_EQ(ring.size(), 4u);
  EXPECT_TRUE(glue_rings({chain({7})}).rings.empty()) << "a way of one node is no ring";
}

TEST(Assemble, DrawsTheRingsThatCloseAndNothingWithoutAnOuter) {
  std::map<std::int64_t, NodeChain> ways{{1, chain({1, 2, 3})},      {2, chain({3, 4, 1})},
                                         {3, chain({10, 11, 12})},  // an outer whose rest is missing
                                         {4, chain({5, 6, 7, 5})}};
  auto find = [&](std::int64_t id) -> const NodeChain* {
    const auto it = ways.find(id);
    return it == ways.end() ? nullptr : &it->second;
  };
  std::size_t open = 0;
  const auto rings = assemble_rings({{1, true}, {2, true}, {3, true}, {99, true}, {4, false}, {98, false}}, find, &open);
  ASSERT_EQ(rings.size(), 2u) << "the glued outer and the inner; the open outer chain is left out";
  EXPECT_EQ(rings[0].size(), 5u);
  EXPECT_EQ(rings[1].size(), 4u);
  EXPECT_EQ(open, 1u);
  EXPECT_TRUE(assemble_rings({{4, false}, {99, true}}, find).empty()) << "no outer member present";
}

TEST(Reader, IncompleteMultipolygonIsDrawnFromItsClosedRings) {
  // An extract that cut part of a forest relation: its outer ring is three open ways (one reversed),
  // one more outer ring lost a member, an inner ring is whole, a member way and a nested relation
  // are absent, and a member with role "" and one with role "label" must be ignored.
  SyntheticMap map(47.5, 10.5);
  const auto a = map.node({0, 0}), b = map.node({100, 0}), c = map.node({100, 100}), d = map.node({0, 100});
  const auto w1 = map.way_through({a, b}, {});
  const auto w2 = map.way_through({c, b}, {});  // reversed
  const auto w3 = map.way_through({c, d, a}, {});
  const auto inner = map.way({{40, 40}, {60, 40}, {60, 60}, {40, 60}}, {}, true);
  const auto e = map.node({300, 0}), f = map.node({400, 0}), g = map.node({400, 100});
  const auto broken = map.way_through({e, f, g}, {});  // its closing member is not in the extract
  const auto stray = map.way({{-300, -300}, {-200, -300}, {-200, -200}, {-300, -300}}, {}, true);
  const auto label = map.node({50, 50});
  map.relation({{'w', w1, "outer"},
                {'w', broken, "outer"},
                {'w', 7777, "outer"},
                {'w', w3, "outer"},
                {'w', inner, "inner"},
                {'w', w2, "outer"},
                {'w', stray, ""},
                {'n', label, "label"},
                {'r', 4242, "outer"}},
               {{"type", "multipolygon"}, {"landuse", "forest"}});
  test::ScratchDir dir;
  map.write(dir / "m.osm.pbf");
  const auto features = read_osm(dir / "m.osm.pbf");
  ASSERT_EQ(features.areas.size(), 1u);
  const auto& forest = features.areas[0];
  EXPECT_EQ(group_name(forest.group), "forest");
  EXPECT_TRUE(forest.from_relation);
  ASSERT_EQ(forest.rings.size(), 2u) << "the glued outer and the inner; not the broken chain nor the stray ring";
  EXPECT_EQ(forest.rings[0].size(), 5u);
  EXPECT_EQ(forest.rings[1].size(), 5u);
  EXPECT_EQ(features.multipolygon_open_chains, 1u);
}

}  // namespace
}  // namespace seqloc::osm
