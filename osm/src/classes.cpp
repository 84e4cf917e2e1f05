#include "seqloc/osm/classes.hpp"

#include <cassert>

namespace seqloc::osm {
namespace {

constexpr std::array<std::string_view, 7> kAreas{"building", "parking", "playground", "grass",
                                                 "park",     "forest",  "water"};
constexpr std::array<std::string_view, 10> kWays{"fence",    "wall", "hedge", "kerb",   "building_outline",
                                                 "cycleway", "path", "road",  "busway", "tree_row"};
// OrienterNet's Patterns.nodes order (conventions.md section 2): a model trained on OrienterNet's
// tiles reads these codes from the nodes channel.
constexpr std::array<std::string_view, 33> kNodes{
    "tree",         "stone",           "crossing",         "lamp",             "traffic_signal",
    "bus_stop",     "stop_sign",       "junction",         "bus_stop_position", "gate",
    "bollard",      "shop",            "restaurant",       "bar",              "pharmacy",
    "fuel",         "bicycle_parking", "charging_station", "parking_entrance", "atm",
    "toilets",      "vending_machine", "fountain",         "waste_basket",     "bench",
    "post_box",     "artwork",         "recycling",        "give_way",         "clock",
    "fire_hydrant", "pole",            "street_cabinet"};

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
