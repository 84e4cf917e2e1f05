#include "seqloc/osm/classes.hpp"

#include <cassert>

namespace seqloc::osm {
namespace {

constexpr std::array<std::string_view, 7> kAreas{"building", "parking", "playground", "grass",
                                                 "park",     "forest",  "water"};
constexpr std::array<std::string_view, 10> kWays{"fence",    "wall", "hedge", "kerb",   "building_outline",
                                                 "cycleway", "path", "road",  "busway", "tree_row"};
// conventions.md order. OrienterNet's Patterns.nodes dict lists a few groups in another order
// (bicycle_parking, waste_basket, artwork); no label matches two node groups, so only the encoding
// differs, and the encoding is the one of conventions.md.
constexpr std::array<std::string_view, 33> kNodes{
    "tree",          "stone",           "crossing",          "lamp",         "traffic_signal",
    "bus_stop",      "stop_sign",       "junction",          "bus_stop_position", "gate",
    "bollard",       "shop",            "restaurant",        "bar",          "pharmacy",
    "fuel",          "charging_station", "parking_entrance", "atm",          "toilets",
    "vending_machine", "fountain",      "bench",             "post_box",     "recycling",
    "clock",         "bicycle_parking", "waste_basket",      "artwork",      "give_way",
    "fire_hydrant",  "pole",            "street_cabinet"};

}  // namespace

std::span<const std::string_view> group_names(Channel channel) {
  switch (channel) {
    case Channel::areas:
      return kAreas;
    case Channel::ways:
      return kWays;
    case Channel::nodes:
      return kNodes;
  }
  assert(false && "invalid channel");
  return {};
}

std::string_view channel_name(Channel channel) {
  switch (channel) {
    case Channel::areas:
      return "areas";
    case Channel::ways:
      return "ways";
    case Channel::nodes:
      return "nodes";
  }
  return "?";
}

std::string_view group_name(Group group) {
  const auto names = group_names(group.channel);
  assert(group.index < names.size());
  return names[group.index];
}

std::optional<Group> find_group(std::string_view name) {
  for (Channel channel : {Channel::areas, Channel::ways, Channel::nodes}) {
    const auto names = group_names(channel);
    for (std::size_t i = 0; i < names.size(); ++i) {
      if (names[i] == name) return Group{channel, static_cast<std::uint8_t>(i)};
    }
  }
  return std::nullopt;
}

}  // namespace seqloc::osm
