// tile_osm: makes a large OSM extract out of real map content by laying copies of one extract side
// by side, for the preprocess_scale benchmark.
//
//   tile_osm INPUT.osm.pbf OUTPUT.osm.pbf COLUMNS ROWS
//
// Copy (i, j) is the input shifted by i times the width of its box in longitude and j times its
// height in latitude (the box is the header's, else the data's), so the copies touch without
// overlapping. Every copy's ids are the input's plus copy * (largest id of that type + 1), node
// references and relation members included, so ids stay unique and, copy after copy, sorted. The
// output holds all nodes, then all ways, then all relations, as a sorted extract does, and its
// header's box is the union of the copies.

#include <algorithm>
#include <cstdio>
#include <cstdlib>
#include <exception>
#include <string>

#include <osmium/io/any_input.hpp>
#include <osmium/io/any_output.hpp>
#include <osmium/osm.hpp>

namespace {

struct Extent {
  osmium::Box box;
  osmium::object_id_type max_id[3] = {0, 0, 0};  // node, way, relation
  long count[3] = {0, 0, 0};
};

int type_index(osmium::item_type type) {
  switch (type) {
    case osmium::item_type::node: return 0;
    case osmium::item_type::way: return 1;
    default: return 2;
  }
}

Extent measure(const std::string& input) {
  Extent extent;
  osmium::io::Reader reader(input);
  extent.box = reader.header().joined_boxes();
  osmium::Box data;
  extent.count[0] = extent.count[1] = extent.count[2] = 0;
  while (osmium::memory::Buffer buffer = reader.read()) {
    for (const auto& object : buffer.select<osmium::OSMObject>()) {
      ++extent.count[type_index(object.type())];
      auto& max = extent.max_id[type_index(object.type())];
      max = std::max(max, object.id());
      if (object.type() == osmium::item_type::node) data.extend(static_cast<const osmium::Node&>(object).location());
    }
  }
  reader.close();
  if (!extent.box.valid()) extent.box = data;
  return extent;
}

// Shifts one copy's objects of one type in place.
void shift(osmium::memory::Buffer& buffer, const Extent& extent, int copy, double dlon, double dlat) {
  auto offset = [&](osmium::item_type type) { return copy * (extent.max_id[type_index(type)] + 1); };
  for (auto& object : buffer.select<osmium::OSMObject>()) {
    object.set_id(object.id() + offset(object.type()));
    if (object.type() == osmium::item_type::node) {
      auto& node = static_cast<osmium::Node&>(object);
      const auto at = node.location();
      node.set_location(osmium::Location(at.lon() + dlon, at.lat() + dlat));
    } else if (object.type() == osmium::item_type::way) {
      for (auto& ref : static_cast<osmium::Way&>(object).nodes()) ref.set_ref(ref.ref() + offset(osmium::item_type::node));
    } else if (object.type() == osmium::item_type::relation) {
      for (auto& member : static_cast<osmium::Relation&>(object).members()) {
        member.set_ref(member.ref() + offset(member.type()));
      }
    }
  }
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 5) {
    std::fprintf(stderr, "usage: %s INPUT.osm.pbf OUTPUT.osm.pbf COLUMNS ROWS\n", argv[0]);
    return 2;
  }
  try {
    const std::string input = argv[1], output = argv[2];
    auto count = [](const char* text) {
      char* end = nullptr;
      const long value = std::strtol(text, &end, 10);
      if (end == text || *end != '\0' || value < 1 || value > 1000) {
        throw std::runtime_error(std::string("'") + text + "': COLUMNS and ROWS must be whole numbers in [1, 1000]");
      }
      return static_cast<int>(value);
    };
    const int columns = count(argv[3]), rows = count(argv[4]);
    const Extent extent = measure(input);
    if (!extent.box.valid()) throw std::runtime_error(input + ": no box in its header and no nodes");
    const double width = extent.box.top_right().lon() - extent.box.bottom_left().lon();
    const double height = extent.box.top_right().lat() - extent.box.bottom_left().lat();
    const osmium::Location low = extent.box.bottom_left();
    const osmium::Location high(low.lon() + static_cast<double>(columns) * width,
                                low.lat() + static_cast<double>(rows) * height);
    if (!high.valid() || high.lat() > 85.0) throw std::runtime_error("the copies would reach beyond lon 180 or lat 85");

    osmium::io::Header header;
    header.set("generator", "seqloc tile_osm");
    header.add_box(osmium::Box(low, high));
    osmium::io::Writer writer(output, header, osmium::io::overwrite::allow);
    for (const auto type : {osmium::osm_entity_bits::node, osmium::osm_entity_bits::way, osmium::osm_entity_bits::relation}) {
      for (int j = 0; j < rows; ++j) {
        for (int i = 0; i < columns; ++i) {
          osmium::io::Reader reader(input, type);
          while (osmium::memory::Buffer buffer = reader.read()) {
            shift(buffer, extent, j * columns + i, static_cast<double>(i) * width, static_cast<double>(j) * height);
            writer(std::move(buffer));
          }
          reader.close();
        }
      }
    }
    writer.close();
    const long copies = static_cast<long>(columns) * rows;
    std::printf("{\"copies\": %ld, \"nodes\": %ld, \"ways\": %ld, \"relations\": %ld}\n", copies,
                copies * extent.count[0], copies * extent.count[1], copies * extent.count[2]);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "tile_osm: %s\n", e.what());
    return 1;
  }
  return 0;
}
