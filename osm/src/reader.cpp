#include "seqloc/osm/reader.hpp"

#include <memory>
#include <string>
#include <system_error>

#include <osmium/area/assembler.hpp>
#include <osmium/area/multipolygon_manager.hpp>
#include <osmium/handler.hpp>
#include <osmium/handler/node_locations_for_ways.hpp>
#include <osmium/index/map/flex_mem.hpp>
#include <osmium/index/map/sparse_mem_array.hpp>
#include <osmium/io/any_input.hpp>
#include <osmium/relations/manager_util.hpp>
#include <osmium/tags/tags_filter.hpp>
#include <osmium/visitor.hpp>

#include "seqloc/osm/classifier.hpp"

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

class FeatureCollector : public osmium::handler::Handler {
 public:
  FeatureCollector(FeatureSet& out, const ReadOptions& options) : out_(out), options_(options) {}

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

  // Areas assembled by libosmium from type=multipolygon relations.
  void area(const osmium::Area& area) {
    if (area.from_way()) return;  // closed ways are classified in way()
    const auto c = classify_multipolygon(view_of(area.tags()));
    if (!c) return;
    AreaFeature feature{c->group, area.orig_id(), true, {}};
    GeoBox box = GeoBox::empty();
    for (const auto& outer : area.outer_rings()) {
      std::vector<GeoPoint> ring;
      for (const auto& ref : outer) ring.push_back(geo_of(ref.location()));
      for (const auto& p : ring) box.extend(p);
      feature.rings.push_back(std::move(ring));
      for (const auto& inner : area.inner_rings(outer)) {
        std::vector<GeoPoint> hole;
        for (const auto& ref : inner) hole.push_back(geo_of(ref.location()));
        feature.rings.push_back(std::move(hole));
      }
    }
    if (feature.rings.empty()) return;
    if (options_.keep_box && !options_.keep_box->intersects(box)) return;
    out_.areas.push_back(std::move(feature));
  }

 private:
  FeatureSet& out_;
  const ReadOptions& options_;
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

// Both passes (multipolygon relations, then everything) over one input, file or buffer. `name`
// names the input in errors.
FeatureSet read_features(const osmium::io::File& file, std::uintmax_t input_bytes, const std::string& name,
                         const ReadOptions& options) {
  FeatureSet out;
  try {
    osmium::area::Assembler::config_type assembler_config;
    assembler_config.create_way_polygons = false;  // OrienterNet's is_area decides for closed ways
    assembler_config.create_old_style_polygons = false;
    osmium::TagsFilter multipolygons{false};
    multipolygons.add_rule(true, osmium::TagMatcher{"type", "multipolygon"});
    osmium::area::MultipolygonManager<osmium::area::Assembler> mp_manager{assembler_config, multipolygons};
    osmium::relations::read_relations(file, mp_manager);

    const auto index = make_location_index(input_bytes);
    LocationHandler locations{*index};
    locations.ignore_errors();  // a way with missing nodes keeps the nodes that exist
    FeatureCollector collector{out, options};

    osmium::io::Reader reader{file, osmium::io::read_meta::no};
    const auto info = header_info(reader.header());
    out.header_box = info.box;
    out.replication_timestamp = info.replication_timestamp;
    osmium::apply(reader, locations, collector, mp_manager.handler([&collector](osmium::memory::Buffer&& buffer) {
                    osmium::apply(buffer, collector);
                  }));
    reader.close();
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
