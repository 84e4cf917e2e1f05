#pragma once
// The semantic classes of the raster (conventions.md section 2): three channels, each a list of
// groups. A pixel stores 0 for background, otherwise 1 + the group's index in its channel's list.

#include <cstdint>
#include <optional>
#include <span>
#include <string_view>

namespace seqloc::osm {

enum class Channel : std::uint8_t { areas = 0, ways = 1, nodes = 2 };
inline constexpr int kChannelCount = 3;

/// A group of one channel, e.g. {ways, 7} is "road". `code()` is its raster value.
struct Group {
  Channel channel;
  std::uint8_t index;  ///< 0-based position in the channel's list

  [[nodiscard]] constexpr std::uint8_t code() const { return static_cast<std::uint8_t>(index + 1); }
  friend constexpr bool operator==(Group, Group) = default;
};

/// Group names of a channel, in list (= encoding and precedence) order.
[[nodiscard]] std::span<const std::string_view> group_names(Channel channel);
[[nodiscard]] std::string_view channel_name(Channel channel);
[[nodiscard]] std::string_view group_name(Group group);
/// The group of that name, searching all channels (names are unique across channels).
[[nodiscard]] std::optional<Group> find_group(std::string_view name);

/// Groups the pipeline refers to by name.
inline constexpr Group kBuildingArea{Channel::areas, 0};
inline constexpr Group kBuildingOutline{Channel::ways, 4};
inline constexpr Group kRoad{Channel::ways, 7};

}  // namespace seqloc::osm
