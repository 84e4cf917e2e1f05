#include "seqloc/osm/reader.hpp"

#include <memory>
#include <string>
#include <system_error>
#include <unordered_map>

#include <osmium/handler.hpp>
#include <osmium/handler/node_locations_for_ways.hpp>
#include <osmium/index/map/flex_mem.hpp>
#include <osmium/index/map/sparse_mem_array.hpp>
#include <osmium/io/any_input.hpp>
#include <osmium/visitor.hpp>

#include "seqloc/osm/classifier.hpp"
#include "seqloc/osm/multipolygon.hpp"

namespace seqloc::osm {
namespace {

using LocationIndex = osmium::index::map::Map<osmium::unsigned_object_id_type, osmium::Location>;
using LocationHandler = osmium::handler::NodeLocationsForWays<LocationIndex>;

// Below this size an extract's nodes fit a sorted sparse array (16 bytes per node, whatever the
// id range). Above, FlexMem switches to a dense array indexed by id once the density of ids makes
// it cheaper (8 bytes per possible id: about 90 GB for the planet, proportionally less for a
// country extract, whose ids are sparse).
constexpr std::uintmax_t kSparseIndexMaxBytes = 512ull << 20;

std::unique_ptr<LocationIndex> make_location_index(std::uintmax_t file_bytes) {
  if (file_bytes <= kSparseIndexMaxBytes) {
    return std::make_unique<osmium::index::map::SparseMemArray<osmium::unsigned_object_id_type, osmium::Location>>();
  }
  return std::make_unique<osmium::index::map::FlexMem<osmium::unsigned_object_id_type, osmium::Location>>();
}

TagView view_of(const osmium::TagList& tags) {
  TagView view;
  for (const auto& tag : tags) view.add(tag.key(), tag.value());
  return view;
}

GeoPoint geo_of(const osmium::Location& location) { return {location.lat(), location.lon()}; }

GeoBox box_of(const std::vector<GeoPoint>& points) {
  GeoBox box = GeoBox::empty();
  for (const auto& p : points) box.extend(p);
  return box;
}

// A classified type=multipolygon relation, waiting for its member ways.
struct PendingRelation {
  Group group;
  std::int64_t id;
  std::vector<RingMember> members;
};

// Pass one: the multipolygon relations that classify, and the ways they need.
class RelationCollector : public osmium::handler::Handler {
 public:
  void relation(const osmium::Relation& relation) {
    const auto c = classify_relation(view_of(relation.tags()));
    if (!c) return;
    PendingRelation pending{c->group, relation.id(), {}};
    for (const auto& member : relation.members()) {
      if (member.type() != osmium::item_type::way) continue;
      const std::string_view role = member.role();
      if (role != "outer" && role != "inner") continue;  // OrienterNet ignores other roles
      pending.members.push_back({member.ref(), role == "outer"});
      member_ways.emplace(member.ref(), std::nullopt);
    }
    if (!pending.members.empty()) relations.push_back(std::move(pending));
  }

  std::vector<PendingRelation> relations;
  /// Every member way; pass two fills in those the input holds.
  std::unordered_map<std::int64_t, std::optional<NodeChain>> member_ways;
};

class FeatureCollector : public osmium::handler::Handler {
 public:
  FeatureCollector(FeatureSet& out, const ReadOptions& options, RelationCollector& relations)
      : out_(out), options_(options), relations_(relations) {}

  void node(const osmium::Node& node) {
    if (!node.location().valid()) return;
    const GeoPoint where = geo_of(node.location());
    out_.data_box.extend(where);
    if (node.tags().empty()) return;
    const auto c = classify_node(view_of(node.tags()));
    if (!c) return;
    if (options_.keep_box && !options_.keep_box->intersects(GeoBox{where.lon_deg, where.lat_deg, where.lon_deg, where.lat_deg})) {
      return;
    }
    out_.points.push_back({c->group, node.id(), where});
  }

  void way(const osmium::Way& way) {
    const auto& refs = way.nodes();
    keep_if_member(way);
    if (refs.size() < 2 || way.tags().empty()) return;
    const bool closed = refs.front().ref() == refs.back().ref();
    const TagView tags = view_of(way.tags());
    const auto c = classify_way(tags, closed);
    if (!c) return;
    std::vector<GeoPoint> points;
    points.reserve(refs.size());
    bool missing = false;
    for (const auto& ref : refs) {
      if (ref.location().valid()) {
        points.push_back(geo_of(ref.location()));
      } else {
        missing = true;
      }
    }
    if (missing) ++out_.ways_missing_nodes;
    if (points.size() < 2) return;
    if (options_.keep_box && !options_.keep_box->intersects(box_of(points))) return;
    if (c->geometry == Geometry::area) {
      if (points.size() < 3) return;
      out_.areas.push_back({c->group, way.id(), false, {std::move(points)}});
    } else {
      const auto* highway = tags.find("highway");
      out_.lines.push_back({c->group, way.id(), highway ? std::string(*highway) : std::string(), std::move(points)});
    }
  }

  // Assembles every pending relation from the member ways pass two kept.
  void assemble_relations() {
    auto find_way = [this](std::int64_t id) -> const NodeChain* {
      const auto it = relations_.member_ways.find(id);
      return it != relations_.member_ways.end() && it->second ? &*it->second : nullptr;
    };
    for (const auto& relation : relations_.relations) {
      auto rings = assemble_rings(relation.members, find_way, &out_.multipolygon_open_chains);
      if (rings.empty()) continue;
      GeoBox box = GeoBox::empty();
      for (const auto& ring : rings) {
        for (const auto& p : ring) box.extend(p);
      }
      if (options_.keep_box && !options_.keep_box->intersects(box)) continue;
      out_.areas.push_back({relation.group, relation.id, true, std::move(rings)});
    }
  }

 private:
  void keep_if_member(const osmium::Way& way) {
    const auto it = relations_.member_ways.find(way.id());
    if (it == relations_.member_ways.end()) return;
    NodeChain chain;
    chain.reserve(way.nodes().size());
    for (const auto& ref : way.nodes()) {
      WayNode node{ref.ref(), std::nullopt};
      if (ref.location().valid()) node.where = geo_of(ref.location());
      chain.push_back(node);
    }
    it->second = std::move(chain);
  }

  FeatureSet& out_;
  const ReadOptions& options_;
  RelationCollector& relations_;
};

void check_readable(const std::filesystem::path& input) {
  std::error_code ec;
  if (!std::filesystem::exists(input, ec)) throw OsmInputError(input.string() + ": no such file");
  if (std::filesystem::is_directory(input, ec)) throw OsmInputError(input.string() + ": is a directory, not an OSM file");
  if (std::filesystem::file_size(input, ec) == 0) throw OsmInputError(input.string() + ": empty file, no OSM data");
}

[[noreturn]] void rethrow_as_input_error(const std::string& input, const std::exception& e) {
  throw OsmInputError(input + ": cannot read OSM data: " + e.what() +
                      " (is the file complete and in a format libosmium reads: .osm.pbf, .osm, .osm.gz, .osm.bz2?)");
}

OsmHeaderInfo header_info(const osmium::io::Header& header) {
  OsmHeaderInfo info;
  const osmium::Box box = header.joined_boxes();
  if (box.valid()) {
    info.box = GeoBox{box.bottom_left().lon(), box.bottom_left().lat(), box.top_right().lon(), box.top_right().lat()};
  }
  info.replication_timestamp = header.get("osmosis_replication_timestamp");
  if (info.replication_timestamp.empty()) info.replication_timestamp = header.get("timestamp");
  info.replication_sequence = header.get("osmosis_replication_sequence_number");
  return info;
}

}  // namespace

OsmHeaderInfo read_osm_header(const std::filesystem::path& input) {
  check_readable(input);
  try {
    osmium::io::Reader reader{osmium::io::File{input.string()}, osmium::osm_entity_bits::nothing};
    auto info = header_info(reader.header());
    reader.close();
    return info;
  } catch (const OsmError&) {
    throw;
  } catch (const std::exception& e) {
    rethrow_as_input_error(input.string(), e);
  }
}

namespace {

// Both passes (multipolygon relations, then nodes and ways) over one input, file or buffer. `name`
// names the input in errors.
FeatureSet read_features(const osmium::io::File& file, std::uintmax_t input_bytes, const std::string& name,
                         const ReadOptions& options) {
  FeatureSet out;
  try {
    RelationCollector relations;
    {
      osmium::io::Reader relation_reader{file, osmium::osm_entity_bits::relation, osmium::io::read_meta::no};
      osmium::apply(relation_reader, relations);
      relation_reader.close();
    }

    const auto index = make_location_index(input_bytes);
    LocationHandler locations{*index};
    locations.ignore_errors();  // a way with missing nodes keeps the nodes that exist
    FeatureCollector collector{out, options, relations};

    osmium::io::Reader reader{file, osmium::osm_entity_bits::node | osmium::osm_entity_bits::way,
                              osmium::io::read_meta::no};
    const auto info = header_info(reader.header());
    out.header_box = info.box;
    out.replication_timestamp = info.replication_timestamp;
    osmium::apply(reader, locations, collector);
    reader.close();
    collector.assemble_relations();
  } catch (const OsmError&) {
    throw;
  } catch (const std::exception& e) {
    rethrow_as_input_error(name, e);
  }
  return out;
}

}  // namespace

FeatureSet read_osm(const std::filesystem::path& input, const ReadOptions& options) {
  check_readable(input);
  std::uintmax_t bytes = 0;
  try {
    bytes = std::filesystem::file_size(input);
  } catch (const std::filesystem::filesystem_error& e) {
    throw OsmInputError(input.string() + ": " + e.code().message());
  }
  return read_features(osmium::io::File{input.string()}, bytes, input.string(), options);
}

FeatureSet read_osm_buffer(std::span<const char> data, std::string_view format, const std::string& name,
                           const ReadOptions& options) {
  if (data.empty()) throw OsmInputError(name + ": empty buffer, no OSM data");
  if (format != "pbf" && format != "xml" && format != "opl") {
    throw OsmInputError(name + ": format '" + std::string(format) + "' is not one of pbf, xml, opl");
  }
  return read_features(osmium::io::File{data.data(), data.size(), std::string(format)}, data.size(), name, options);
}

}  // namespace seqloc::osm
