#include "seqloc/osm/classifier.hpp"

#include <algorithm>
#include <array>
#include <cctype>
#include <cstdlib>

namespace seqloc::osm {
namespace {

// OrienterNet's regular expressions are all of the form "prefix(alt1|alt2|...)" applied with
// re.match, i.e. they test whether the label *starts with* one of the alternatives. The single
// exception is road's ".*_link", which matches "highway:" followed by anything containing "_link".
// Each alternative is written out here; the comment above each group is OrienterNet's pattern.
struct Alternative {
  std::string_view prefix;
  std::string_view then_contains;  ///< non-empty: the rest of the label must contain this
};
struct Pattern {
  std::string_view group;
  std::vector<Alternative> alternatives;
};

const std::vector<Pattern>& area_patterns() {
  static const std::vector<Pattern> patterns{
      // building($|:.*?)*   -- "(...)*" may match nothing, so any label starting with "building"
      {"building", {{"building", {}}}},
      // amenity:parking
      {"parking", {{"amenity:parking", {}}}},
      // leisure:(playground|pitch)
      {"playground", {{"leisure:playground", {}}, {"leisure:pitch", {}}}},
      // (landuse:grass|landcover:grass|landuse:meadow|landuse:flowerbed|natural:grassland)
      {"grass",
       {{"landuse:grass", {}}, {"landcover:grass", {}}, {"landuse:meadow", {}}, {"landuse:flowerbed", {}},
        {"natural:grassland", {}}}},
      // leisure:(park|garden|dog_park)
      {"park", {{"leisure:park", {}}, {"leisure:garden", {}}, {"leisure:dog_park", {}}}},
      // (landuse:forest|natural:wood)
      {"forest", {{"landuse:forest", {}}, {"natural:wood", {}}}},
      // (natural:water|waterway:*)   -- ":*" may match nothing: any label starting with "waterway"
      {"water", {{"natural:water", {}}, {"waterway", {}}}},
  };
  return patterns;
}

const std::vector<Pattern>& way_patterns() {
  static const std::vector<Pattern> patterns{
      {"fence", {{"barrier:fence", {}}, {"barrier:yes", {}}}},
      {"wall", {{"barrier:wall", {}}, {"barrier:retaining_wall", {}}}},
      {"hedge", {{"barrier:hedge", {}}}},
      {"kerb", {{"barrier:kerb", {}}}},
      {"building_outline", {{"building", {}}}},
      {"cycleway", {{"highway:cycleway", {}}}},
      // highway:(pedestrian|footway|steps|path|corridor)
      {"path",
       {{"highway:pedestrian", {}}, {"highway:footway", {}}, {"highway:steps", {}}, {"highway:path", {}},
        {"highway:corridor", {}}}},
      // highway:(motorway|trunk|primary|secondary|tertiary|service|construction|track|
      //          unclassified|residential|.*_link)
      {"road",
       {{"highway:motorway", {}},
        {"highway:trunk", {}},
        {"highway:primary", {}},
        {"highway:secondary", {}},
        {"highway:tertiary", {}},
        {"highway:service", {}},
        {"highway:construction", {}},
        {"highway:track", {}},
        {"highway:unclassified", {}},
        {"highway:residential", {}},
        {"highway:", "_link"}}},
      {"busway", {{"highway:busway", {}}}},
      {"tree_row", {{"natural:tree_row", {}}}},
  };
  return patterns;
}

const std::vector<Pattern>& node_patterns() {
  static const std::vector<Pattern> patterns{
      {"tree", {{"natural:tree", {}}}},
      {"stone", {{"natural:stone", {}}, {"barrier:block", {}}}},
      {"crossing", {{"highway:crossing", {}}}},
      {"lamp", {{"highway:street_lamp", {}}}},
      {"traffic_signal", {{"highway:traffic_signals", {}}}},
      {"bus_stop", {{"highway:bus_stop", {}}}},
      {"stop_sign", {{"highway:stop", {}}}},
      {"junction", {{"highway:motorway_junction", {}}}},
      {"bus_stop_position", {{"public_transport:stop_position", {}}}},
      {"gate",
       {{"barrier:gate", {}}, {"barrier:lift_gate", {}}, {"barrier:swing_gate", {}}, {"barrier:cycle_barrier", {}}}},
      {"bollard", {{"barrier:bollard", {}}}},
      // (shop.*?|amenity:(bank|post_office))
      {"shop", {{"shop", {}}, {"amenity:bank", {}}, {"amenity:post_office", {}}}},
      {"restaurant", {{"amenity:restaurant", {}}, {"amenity:fast_food", {}}}},
      {"bar", {{"amenity:cafe", {}}, {"amenity:bar", {}}, {"amenity:pub", {}}, {"amenity:biergarten", {}}}},
      {"pharmacy", {{"amenity:pharmacy", {}}}},
      {"fuel", {{"amenity:fuel", {}}}},
      {"bicycle_parking", {{"amenity:bicycle_parking", {}}, {"amenity:bicycle_rental", {}}}},
      {"charging_station", {{"amenity:charging_station", {}}}},
      {"parking_entrance", {{"amenity:parking_entrance", {}}}},
      {"atm", {{"amenity:atm", {}}}},
      {"toilets", {{"amenity:toilets", {}}}},
      {"vending_machine", {{"amenity:vending_machine", {}}}},
      {"fountain", {{"amenity:fountain", {}}}},
      {"waste_basket", {{"amenity:waste_basket", {}}, {"amenity:waste_disposal", {}}}},
      {"bench", {{"amenity:bench", {}}}},
      {"post_box", {{"amenity:post_box", {}}}},
      {"artwork", {{"tourism:artwork", {}}}},
      {"recycling", {{"amenity:recycling", {}}}},
      {"give_way", {{"highway:give_way", {}}}},
      {"clock", {{"amenity:clock", {}}}},
      {"fire_hydrant", {{"emergency:fire_hydrant", {}}}},
      {"pole", {{"man_made:flagpole", {}}, {"man_made:utility_pole", {}}}},
      {"street_cabinet", {{"man_made:street_cabinet", {}}}},
  };
  return patterns;
}

const std::vector<Pattern>& patterns_of(Channel channel) {
  switch (channel) {
    case Channel::areas:
      return area_patterns();
    case Channel::ways:
      return way_patterns();
    case Channel::nodes:
      break;
  }
  return node_patterns();
}

bool matches(std::string_view label, const Alternative& alt) {
  if (!label.starts_with(alt.prefix)) return false;
  return alt.then_contains.empty() || label.substr(alt.prefix.size()).find(alt.then_contains) != std::string_view::npos;
}

// parser.IGNORE_TAGS
bool is_ignored_key(std::string_view key) {
  static constexpr std::array<std::string_view, 6> kIgnored{"source", "phone", "entrance", "inscription", "note",
                                                            "name"};
  return std::find(kIgnored.begin(), kIgnored.end(), key) != kIgnored.end();
}

bool has_relevant_tags(const TagView& tags) {
  return std::any_of(tags.tags().begin(), tags.tags().end(), [](const auto& t) { return !is_ignored_key(t.first); });
}

// Python's float() on one token (after parse_levels removed spaces): surrounding whitespace,
// a sign, inf/infinity/nan, or a decimal literal whose digits may be grouped by single
// underscores. Returns nullopt where Python raises ValueError.
std::optional<double> python_float(std::string_view text) {
  auto is_space = [](char c) { return std::isspace(static_cast<unsigned char>(c)) != 0; };
  while (!text.empty() && is_space(text.front())) text.remove_prefix(1);
  while (!text.empty() && is_space(text.back())) text.remove_suffix(1);
  std::string clean;
  std::size_t i = 0;
  if (i < text.size() && (text[i] == '+' || text[i] == '-')) clean += text[i++];
  std::string rest;
  for (std::size_t j = i; j < text.size(); ++j) rest += static_cast<char>(std::tolower(static_cast<unsigned char>(text[j])));
  if (rest == "inf" || rest == "infinity" || rest == "nan") {
    clean += rest;
    return std::strtod(clean.c_str(), nullptr);
  }
  auto digits = [&](bool required) {
    // digit (_? digit)*
    std::size_t count = 0;
    while (i < text.size()) {
      if (std::isdigit(static_cast<unsigned char>(text[i]))) {
        clean += text[i++];
        ++count;
      } else if (text[i] == '_' && count > 0 && i + 1 < text.size() &&
                 std::isdigit(static_cast<unsigned char>(text[i + 1]))) {
        ++i;
      } else {
        break;
      }
    }
    return count > 0 || !required;
  };
  std::size_t mantissa_start = clean.size();
  digits(false);
  std::size_t int_digits = clean.size() - mantissa_start;
  std::size_t frac_digits = 0;
  if (i < text.size() && text[i] == '.') {
    clean += text[i++];
    const std::size_t before = clean.size();
    digits(false);
    frac_digits = clean.size() - before;
  }
  if (int_digits + frac_digits == 0) return std::nullopt;
  if (i < text.size() && (text[i] == 'e' || text[i] == 'E')) {
    clean += text[i++];
    if (i < text.size() && (text[i] == '+' || text[i] == '-')) clean += text[i++];
    if (!digits(true)) return std::nullopt;
  }
  if (i != text.size()) return std::nullopt;
  return std::strtod(clean.c_str(), nullptr);
}

std::optional<Group> match_in_order(std::string_view label, std::initializer_list<Channel> order) {
  for (Channel channel : order) {
    if (auto group = match_group(label, channel)) return group;
  }
  return std::nullopt;
}

}  // namespace

std::vector<double> parse_levels(std::string_view text) {
  std::string cleaned;
  for (char c : text) {
    if (c == ',') {
      cleaned += ';';
    } else if (c != ' ') {
      cleaned += c;
    }
  }
  std::vector<double> levels;
  std::size_t start = 0;
  while (true) {
    const std::size_t end = cleaned.find(';', start);
    const auto token = std::string_view(cleaned).substr(start, end == std::string::npos ? std::string::npos : end - start);
    const auto value = python_float(token);
    if (!value) return {};
    levels.push_back(*value);
    if (end == std::string::npos) break;
    start = end + 1;
  }
  return levels;
}

bool passes_level_filter(const TagView& tags) {
  if (const auto* level = tags.find("level")) {
    const auto levels = parse_levels(*level);
    const bool ground = std::any_of(levels.begin(), levels.end(), [](double l) { return l == 0.0 || l == 1.0; });
    if (!ground) return false;
  }
  if (const auto* layer = tags.find("layer")) {
    const auto layers = parse_levels(*layer);
    if (!layers.empty()) {
      // Python's max(): keeps the first element unless a later one compares greater (NaN-aware).
      double top = layers.front();
      for (double l : layers) {
        if (l > top) top = l;
      }
      if (top < 0.0) return false;
    }
  }
  const auto* location = tags.find("location");
  const auto* parking = tags.find("parking");
  return !(location && *location == "underground") && !(parking && *parking == "underground");
}

bool is_area(const TagView& tags, bool closed) {
  if (!closed) return false;
  if (const auto* area = tags.find("area"); area && *area == "no") return false;
  for (std::string_view key :
       {"area", "building", "amenity", "indoor", "landuse", "landcover", "leisure", "public_transport", "shop"}) {
    if (const auto* value = tags.find(key); value && *value != "no") return true;
  }
  if (const auto* natural = tags.find("natural")) {
    return *natural == "wood" || *natural == "grassland" || *natural == "water";
  }
  return false;
}

std::optional<std::string> node_label(const TagView& tags) {
  for (std::string_view key : {"amenity", "natural", "highway", "barrier", "shop", "tourism", "public_transport",
                               "emergency", "man_made"}) {
    const auto* value = tags.find(key);
    if (!value) continue;
    if (value->find("disused") != std::string_view::npos) continue;
    return std::string(key) + ":" + std::string(*value);
  }
  return std::nullopt;
}

std::optional<std::string> way_label(const TagView& tags) {
  for (std::string_view key : {"highway", "barrier", "natural"}) {
    if (const auto* value = tags.find(key)) return std::string(key) + ":" + std::string(*value);
  }
  return std::nullopt;
}

std::optional<std::string> area_label(const TagView& tags) {
  if (const auto* building = tags.find("building")) {
    std::string kind(*building);
    if (kind == "yes") {
      for (std::string_view key : {"amenity", "tourism"}) {
        if (const auto* value = tags.find(key)) {
          kind = *value;
          break;
        }
      }
    }
    return kind == "yes" ? std::string("building") : "building:" + kind;
  }
  if (const auto* area_highway = tags.find("area:highway")) return "highway:" + std::string(*area_highway);
  for (std::string_view key :
       {"amenity", "landcover", "leisure", "shop", "highway", "tourism", "natural", "waterway", "landuse"}) {
    if (const auto* value = tags.find(key)) return std::string(key) + ":" + std::string(*value);
  }
  return std::nullopt;
}

std::optional<Group> match_group(std::string_view label, Channel channel) {
  const auto& patterns = patterns_of(channel);
  for (const auto& pattern : patterns) {
    for (const auto& alt : pattern.alternatives) {
      if (matches(label, alt)) {
        const auto group = find_group(pattern.group);
        return group;
      }
    }
  }
  return std::nullopt;
}

std::optional<Classification> classify_node(const TagView& tags) {
  if (!has_relevant_tags(tags) || !passes_level_filter(tags)) return std::nullopt;
  auto label = node_label(tags);
  if (!label) return std::nullopt;
  const auto group = match_in_order(*label, {Channel::nodes, Channel::ways});
  if (!group) return std::nullopt;
  return Classification{Geometry::point, *group, std::move(*label)};
}

std::optional<Classification> classify_way(const TagView& tags, bool closed) {
  const bool level_ok = passes_level_filter(tags);
  if (has_relevant_tags(tags) && is_area(tags, closed) && level_ok) {
    // parser.filter_way excludes every way that filter_area keeps, labelled or not.
    auto label = area_label(tags);
    if (!label) return std::nullopt;
    const auto group = match_in_order(*label, {Channel::areas, Channel::ways, Channel::nodes});
    if (!group) return std::nullopt;
    return Classification{Geometry::area, *group, std::move(*label)};
  }
  if (tags.empty() || !level_ok) return std::nullopt;
  auto label = way_label(tags);
  if (!label) return std::nullopt;
  const auto group = match_in_order(*label, {Channel::ways, Channel::nodes});
  if (!group) return std::nullopt;
  return Classification{Geometry::line, *group, std::move(*label)};
}

std::optional<Classification> classify_relation(const TagView& tags) {
  const auto* type = tags.find("type");
  if (!type || *type != "multipolygon") return std::nullopt;
  auto label = area_label(tags);
  if (!label) return std::nullopt;
  const auto group = match_in_order(*label, {Channel::areas, Channel::ways, Channel::nodes});
  if (!group) return std::nullopt;
  return Classification{Geometry::area, *group, std::move(*label)};
}

}  // namespace seqloc::osm
