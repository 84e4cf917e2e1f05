// OrienterNet's tag rules (maploc/osm/parser.py) as tables: label -> group, element -> drawn or
// not, with the quirks of Python's re.match (prefix matching) spelled out.

#include <array>
#include <cmath>
#include <optional>
#include <string>

#include <gtest/gtest.h>

#include "seqloc/osm/classifier.hpp"

namespace seqloc::osm {
namespace {

struct LabelCase {
  const char* label;
  Channel channel;
  const char* group;  // nullptr: no group of that channel
};

class LabelToGroup : public ::testing::TestWithParam<LabelCase> {};

TEST_P(LabelToGroup, MatchesOrienterNetPatterns) {
  const auto& c = GetParam();
  const auto group = match_group(c.label, c.channel);
  if (c.group == nullptr) {
    EXPECT_FALSE(group.has_value()) << c.label << " matched " << group_name(*group);
  } else {
    ASSERT_TRUE(group.has_value()) << c.label;
    EXPECT_EQ(group_name(*group), c.group) << c.label;
    EXPECT_EQ(group->channel, c.channel);
  }
}

INSTANTIATE_TEST_SUITE_P(
    Areas, LabelToGroup,
    ::testing::Values(LabelCase{"building", Channel::areas, "building"},
                      LabelCase{"building:house", Channel::areas, "building"},
                      LabelCase{"buildingfoo", Channel::areas, "building"},  // "(...)*" may match nothing
                      LabelCase{"amenity:parking", Channel::areas, "parking"},
                      LabelCase{"amenity:parking_space", Channel::areas, "parking"},  // prefix
                      LabelCase{"leisure:pitch", Channel::areas, "playground"},
                      LabelCase{"landuse:meadow", Channel::areas, "grass"},
                      LabelCase{"landcover:grass", Channel::areas, "grass"},
                      LabelCase{"natural:grassland", Channel::areas, "grass"},
                      LabelCase{"leisure:dog_park", Channel::areas, "park"},
                      LabelCase{"landuse:forest", Channel::areas, "forest"},
                      LabelCase{"natural:wood", Channel::areas, "forest"},
                      LabelCase{"natural:water", Channel::areas, "water"},
                      LabelCase{"natural:waterfall", Channel::areas, "water"},  // prefix of natural:water
                      LabelCase{"waterway:riverbank", Channel::areas, "water"},
                      LabelCase{"waterway", Channel::areas, "water"},
                      LabelCase{"landuse:farmland", Channel::areas, nullptr},
                      LabelCase{"natural:scrub", Channel::areas, nullptr}));

INSTANTIATE_TEST_SUITE_P(
    Ways, LabelToGroup,
    ::testing::Values(LabelCase{"barrier:fence", Channel::ways, "fence"},
                      LabelCase{"barrier:yes", Channel::ways, "fence"},
                      LabelCase{"barrier:retaining_wall", Channel::ways, "wall"},
                      LabelCase{"barrier:hedge", Channel::ways, "hedge"},
                      LabelCase{"barrier:kerb", Channel::ways, "kerb"},
                      LabelCase{"building:yes", Channel::ways, "building_outline"},
                      LabelCase{"highway:cycleway", Channel::ways, "cycleway"},
                      LabelCase{"highway:footway", Channel::ways, "path"},
                      LabelCase{"highway:steps", Channel::ways, "path"},
                      LabelCase{"highway:track", Channel::ways, "road"},
                      LabelCase{"highway:residential", Channel::ways, "road"},
                      LabelCase{"highway:unclassified", Channel::ways, "road"},
                      LabelCase{"highway:motorway_link", Channel::ways, "road"},
                      LabelCase{"highway:tertiary_link", Channel::ways, "road"},
                      LabelCase{"highway:foo_link", Channel::ways, "road"},       // ".*_link"
                      LabelCase{"highway:services", Channel::ways, "road"},       // prefix of service
                      LabelCase{"highway:cycleway_link", Channel::ways, "cycleway"},  // first group wins
                      LabelCase{"highway:busway", Channel::ways, "busway"},
                      LabelCase{"highway:living_street", Channel::ways, nullptr},  // not in OrienterNet's list
                      LabelCase{"highway:road", Channel::ways, nullptr},
                      LabelCase{"natural:tree_row", Channel::ways, "tree_row"},
                      LabelCase{"waterway:stream", Channel::ways, nullptr}));

INSTANTIATE_TEST_SUITE_P(
    Nodes, LabelToGroup,
    ::testing::Values(LabelCase{"natural:tree", Channel::nodes, "tree"},
                      LabelCase{"natural:tree_row", Channel::nodes, "tree"},  // prefix of natural:tree
                      LabelCase{"barrier:block", Channel::nodes, "stone"},
                      LabelCase{"highway:street_lamp", Channel::nodes, "lamp"},
                      LabelCase{"highway:stop", Channel::nodes, "stop_sign"},
                      LabelCase{"highway:motorway_junction", Channel::nodes, "junction"},
                      LabelCase{"public_transport:stop_position", Channel::nodes, "bus_stop_position"},
                      LabelCase{"barrier:lift_gate", Channel::nodes, "gate"},
                      LabelCase{"shop:bakery", Channel::nodes, "shop"},
                      LabelCase{"amenity:bank", Channel::nodes, "shop"},
                      LabelCase{"amenity:fast_food", Channel::nodes, "restaurant"},
                      LabelCase{"amenity:biergarten", Channel::nodes, "bar"},
                      LabelCase{"amenity:bicycle_rental", Channel::nodes, "bicycle_parking"},
                      LabelCase{"amenity:waste_disposal", Channel::nodes, "waste_basket"},
                      LabelCase{"tourism:artwork", Channel::nodes, "artwork"},
                      LabelCase{"emergency:fire_hydrant", Channel::nodes, "fire_hydrant"},
                      LabelCase{"man_made:utility_pole", Channel::nodes, "pole"},
                      LabelCase{"man_made:street_cabinet", Channel::nodes, "street_cabinet"},
                      LabelCase{"amenity:school", Channel::nodes, nullptr},
                      LabelCase{"highway:bus_stop", Channel::nodes, "bus_stop"}));

TEST(Encoding, CodesFollowConventionsLists) {
  // conventions.md section 2: 0 background, else 1 + index in the list.
  EXPECT_EQ(find_group("building")->code(), 1);
  EXPECT_EQ(find_group("water")->code(), 7);
  EXPECT_EQ(find_group("road")->code(), 8);
  EXPECT_EQ(find_group("tree_row")->code(), 10);
  EXPECT_EQ(find_group("tree")->code(), 1);
  EXPECT_EQ(find_group("bicycle_parking")->code(), 17);
  EXPECT_EQ(find_group("bench")->code(), 25);
  EXPECT_EQ(find_group("street_cabinet")->code(), 33);
  EXPECT_EQ(group_names(Channel::areas).size(), 7u);
  EXPECT_EQ(group_names(Channel::ways).size(), 10u);
  EXPECT_EQ(group_names(Channel::nodes).size(), 33u);
  EXPECT_EQ(kRoad, *find_group("road"));
  EXPECT_EQ(kBuildingOutline, *find_group("building_outline"));
}

// The whole pattern table: for every group of every channel, one label OrienterNet's pattern
// matches and the code a model trained on OrienterNet's tiles reads for it (Patterns.areas,
// .ways, .nodes in dict order; codes written out from conventions.md section 2, not computed).
struct TableRow {
  Channel channel;
  const char* label;
  const char* group;
  int code;
};

TEST(Encoding, EveryGroupOfThePatternTableHasOrienterNetsCode) {
  const std::vector<TableRow> table{
      {Channel::areas, "building", "building", 1},
      {Channel::areas, "amenity:parking", "parking", 2},
      {Channel::areas, "leisure:pitch", "playground", 3},
      {Channel::areas, "landuse:meadow", "grass", 4},
      {Channel::areas, "leisure:garden", "park", 5},
      {Channel::areas, "natural:wood", "forest", 6},
      {Channel::areas, "waterway:riverbank", "water", 7},
      {Channel::ways, "barrier:yes", "fence", 1},
      {Channel::ways, "barrier:retaining_wall", "wall", 2},
      {Channel::ways, "barrier:hedge", "hedge", 3},
      {Channel::ways, "barrier:kerb", "kerb", 4},
      {Channel::ways, "building:house", "building_outline", 5},
      {Channel::ways, "highway:cycleway", "cycleway", 6},
      {Channel::ways, "highway:steps", "path", 7},
      {Channel::ways, "highway:primary_link", "road", 8},
      {Channel::ways, "highway:busway", "busway", 9},
      {Channel::ways, "natural:tree_row", "tree_row", 10},
      {Channel::nodes, "natural:tree", "tree", 1},
      {Channel::nodes, "natural:stone", "stone", 2},
      {Channel::nodes, "highway:crossing", "crossing", 3},
      {Channel::nodes, "highway:street_lamp", "lamp", 4},
      {Channel::nodes, "highway:traffic_signals", "traffic_signal", 5},
      {Channel::nodes, "highway:bus_stop", "bus_stop", 6},
      {Channel::nodes, "highway:stop", "stop_sign", 7},
      {Channel::nodes, "highway:motorway_junction", "junction", 8},
      {Channel::nodes, "public_transport:stop_position", "bus_stop_position", 9},
      {Channel::nodes, "barrier:cycle_barrier", "gate", 10},
      {Channel::nodes, "barrier:bollard", "bollard", 11},
      {Channel::nodes, "amenity:post_office", "shop", 12},
      {Channel::nodes, "amenity:restaurant", "restaurant", 13},
      {Channel::nodes, "amenity:pub", "bar", 14},
      {Channel::nodes, "amenity:pharmacy", "pharmacy", 15},
      {Channel::nodes, "amenity:fuel", "fuel", 16},
      {Channel::nodes, "amenity:bicycle_parking", "bicycle_parking", 17},
      {Channel::nodes, "amenity:charging_station", "charging_station", 18},
      {Channel::nodes, "amenity:parking_entrance", "parking_entrance", 19},
      {Channel::nodes, "amenity:atm", "atm", 20},
      {Channel::nodes, "amenity:toilets", "toilets", 21},
      {Channel::nodes, "amenity:vending_machine", "vending_machine", 22},
      {Channel::nodes, "amenity:fountain", "fountain", 23},
      {Channel::nodes, "amenity:waste_basket", "waste_basket", 24},
      {Channel::nodes, "amenity:bench", "bench", 25},
      {Channel::nodes, "amenity:post_box", "post_box", 26},
      {Channel::nodes, "tourism:artwork", "artwork", 27},
      {Channel::nodes, "amenity:recycling", "recycling", 28},
      {Channel::nodes, "highway:give_way", "give_way", 29},
      {Channel::nodes, "amenity:clock", "clock", 30},
      {Channel::nodes, "emergency:fire_hydrant", "fire_hydrant", 31},
      {Channel::nodes, "man_made:flagpole", "pole", 32},
      {Channel::nodes, "man_made:street_cabinet", "street_cabinet", 33},
  };
  std::array<std::size_t, kChannelCount> rows_per_channel{};
  for (const auto& row : table) {
    SCOPED_TRACE(row.label);
    const auto group = match_group(row.label, row.channel);
    ASSERT_TRUE(group.has_value());
    EXPECT_EQ(group_name(*group), row.group);
    EXPECT_EQ(group->code(), row.code);
    // The list position is the code: the table walks each channel's list in order.
    const auto names = group_names(row.channel);
    const std::size_t position = rows_per_channel[static_cast<std::size_t>(row.channel)]++;
    ASSERT_LT(position, names.size());
    EXPECT_EQ(names[position], row.group);
  }
  for (Channel channel : {Channel::areas, Channel::ways, Channel::nodes}) {
    EXPECT_EQ(rows_per_channel[static_cast<std::size_t>(channel)], group_names(channel).size()) << channel_name(channel);
  }
}

TEST(Levels, ParsesLikePythonFloat) {
  EXPECT_EQ(parse_levels("0;1"), (std::vector<double>{0, 1}));
  EXPECT_EQ(parse_levels("0, 1"), (std::vector<double>{0, 1}));
  EXPECT_EQ(parse_levels("-1"), (std::vector<double>{-1}));
  EXPECT_EQ(parse_levels("1_0"), (std::vector<double>{10}));
  EXPECT_EQ(parse_levels("1e1"), (std::vector<double>{10}));
  EXPECT_EQ(parse_levels(".5"), (std::vector<double>{0.5}));
  EXPECT_TRUE(std::isinf(parse_levels("inf").at(0)));
  EXPECT_TRUE(parse_levels("").empty());
  EXPECT_TRUE(parse_levels("1;").empty());  // float('') raises: the whole list is dropped
  EXPECT_TRUE(parse_levels("abc").empty());
  EXPECT_TRUE(parse_levels("1__0").empty());
  EXPECT_TRUE(parse_levels("_1").empty());
}

struct ElementCase {
  const char* what;
  enum Kind { node, open_way, closed_way, relation } kind;
  TagView tags;
  std::optional<Geometry> geometry;  // nullopt: not drawn
  const char* group;
};

class ElementClassification : public ::testing::TestWithParam<ElementCase> {};

TEST_P(ElementClassification, FollowsOrienterNetFilters) {
  const auto& c = GetParam();
  std::optional<Classification> result;
  switch (c.kind) {
    case ElementCase::node:
      result = classify_node(c.tags);
      break;
    case ElementCase::open_way:
      result = classify_way(c.tags, false);
      break;
    case ElementCase::closed_way:
      result = classify_way(c.tags, true);
      break;
    case ElementCase::relation:
      result = classify_relation(c.tags);
      break;
  }
  if (!c.geometry) {
    EXPECT_FALSE(result.has_value()) << c.what << " was drawn as " << (result ? result->label : "");
    return;
  }
  ASSERT_TRUE(result.has_value()) << c.what;
  EXPECT_EQ(result->geometry, *c.geometry) << c.what;
  EXPECT_EQ(group_name(result->group), c.group) << c.what;
}

using E = ElementCase;
INSTANTIATE_TEST_SUITE_P(
    Elements, ElementClassification,
    ::testing::Values(
        E{"bench node", E::node, {{"amenity", "bench"}}, Geometry::point, "bench"},
        E{"kerb node falls back to ways", E::node, {{"barrier", "kerb"}}, Geometry::point, "kerb"},
        E{"name-only node", E::node, {{"name", "X"}, {"source", "survey"}}, std::nullopt, nullptr},
        E{"disused amenity skips to next key", E::node, {{"amenity", "disused:bench"}, {"natural", "tree"}},
          Geometry::point, "tree"},
        E{"key precedence: amenity before highway", E::node, {{"highway", "street_lamp"}, {"amenity", "bench"}},
          Geometry::point, "bench"},
        E{"level 2 is dropped", E::node, {{"amenity", "bench"}, {"level", "2"}}, std::nullopt, nullptr},
        E{"level 0;1 is kept", E::node, {{"amenity", "bench"}, {"level", "0;1"}}, Geometry::point, "bench"},
        E{"level 1 is kept (US ground floor)", E::node, {{"amenity", "bench"}, {"level", "1"}}, Geometry::point,
          "bench"},
        E{"unparseable level is dropped", E::node, {{"amenity", "bench"}, {"level", "ground"}}, std::nullopt, nullptr},
        E{"negative layer is dropped", E::node, {{"amenity", "bench"}, {"layer", "-1"}}, std::nullopt, nullptr},
        E{"layer -1;1 is kept (max >= 0)", E::node, {{"amenity", "bench"}, {"layer", "-1;1"}}, Geometry::point,
          "bench"},
        E{"unparseable layer is kept", E::node, {{"amenity", "bench"}, {"layer", "x"}}, Geometry::point, "bench"},
        E{"underground location", E::node, {{"amenity", "bench"}, {"location", "underground"}}, std::nullopt, nullptr},
        E{"underground parking", E::closed_way, {{"amenity", "parking"}, {"parking", "underground"}}, std::nullopt,
          nullptr},
        E{"closed building is an area", E::closed_way, {{"building", "yes"}}, Geometry::area, "building"},
        E{"building=yes takes amenity kind", E::closed_way, {{"building", "yes"}, {"amenity", "school"}},
          Geometry::area, "building"},
        E{"open building way is dropped", E::open_way, {{"building", "yes"}}, std::nullopt, nullptr},
        E{"closed residential road is a line", E::closed_way, {{"highway", "residential"}}, Geometry::line, "road"},
        E{"pedestrian area is a filled path", E::closed_way, {{"highway", "pedestrian"}, {"area", "yes"}},
          Geometry::area, "path"},
        E{"area=no is not an area", E::closed_way, {{"landuse", "forest"}, {"area", "no"}}, std::nullopt, nullptr},
        E{"natural=wood is an area", E::closed_way, {{"natural", "wood"}}, Geometry::area, "forest"},
        E{"natural=scrub is neither", E::closed_way, {{"natural", "scrub"}}, std::nullopt, nullptr},
        E{"fountain area drawn in nodes channel", E::closed_way, {{"amenity", "fountain"}}, Geometry::area,
          "fountain"},
        E{"area:highway takes precedence", E::closed_way, {{"area:highway", "primary"}, {"area", "yes"}},
          Geometry::area, "road"},
        E{"tunnel road below ground", E::open_way, {{"highway", "track"}, {"layer", "-1"}}, std::nullopt, nullptr},
        E{"building on level 3 is dropped", E::closed_way, {{"building", "yes"}, {"level", "3"}}, std::nullopt,
          nullptr},
        E{"hedge line", E::open_way, {{"barrier", "hedge"}}, Geometry::line, "hedge"},
        E{"waterway line has no way label", E::open_way, {{"waterway", "stream"}}, std::nullopt, nullptr},
        E{"multipolygon forest", E::relation, {{"type", "multipolygon"}, {"landuse", "forest"}}, Geometry::area,
          "forest"},
        E{"boundary relation", E::relation, {{"type", "boundary"}, {"landuse", "forest"}}, std::nullopt, nullptr},
        E{"relations ignore levels", E::relation, {{"type", "multipolygon"}, {"building", "yes"}, {"level", "5"}},
          Geometry::area, "building"}));

}  // namespace
}  // namespace seqloc::osm
