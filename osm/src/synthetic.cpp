#include "seqloc/osm/synthetic.hpp"

#include <algorithm>
#include <cmath>

#include <osmium/builder/osm_object_builder.hpp>
#include <osmium/io/any_output.hpp>
#include <osmium/memory/buffer.hpp>

#include "seqloc/core/angles.hpp"
#include "seqloc/osm/errors.hpp"

namespace seqloc::osm {

struct SyntheticMap::Impl {
  struct Node {
    std::int64_t id;
    GeoPoint where;
    Tags tags;
  };
  struct Way {
    std::int64_t id;
    std::vector<std::int64_t> nodes;
    Tags tags;
  };
  struct Relation {
    std::int64_t id;
    std::vector<SyntheticMap::Member> members;
    Tags tags;
  };
  std::vector<Node> nodes;
  std::vector<Way> ways;
  std::vector<Relation> relations;
};

SyntheticMap::SyntheticMap(double lat0_deg, double lon0_deg)
    : projection_(lat0_deg, lon0_deg), impl_(std::make_unique<Impl>()) {}
SyntheticMap::~SyntheticMap() = default;
SyntheticMap::SyntheticMap(SyntheticMap&&) noexcept = default;
SyntheticMap& SyntheticMap::operator=(SyntheticMap&&) noexcept = default;

std::int64_t SyntheticMap::node(LocalPoint p, const Tags& tags) {
  const auto id = static_cast<std::int64_t>(impl_->nodes.size()) + 1;
  impl_->nodes.push_back({id, to_geo(p), tags});
  return id;
}

std::int64_t SyntheticMap::way(const std::vector<LocalPoint>& points, const Tags& tags, bool closed) {
  std::vector<std::int64_t> ids;
  ids.reserve(points.size() + 1);
  for (const auto& p : points) ids.push_back(node(p));
  if (closed && !ids.empty()) ids.push_back(ids.front());
  return way_through(ids, tags);
}

std::int64_t SyntheticMap::way_through(const std::vector<std::int64_t>& node_ids, const Tags& tags) {
  const auto id = static_cast<std::int64_t>(impl_->ways.size()) + 1;
  impl_->ways.push_back({id, node_ids, tags});
  return id;
}

std::int64_t SyntheticMap::multipolygon(const std::vector<std::vector<LocalPoint>>& outers,
                                        const std::vector<std::vector<LocalPoint>>& inners, Tags tags) {
  std::vector<Member> members;
  members.reserve(outers.size() + inners.size());
  for (const auto& ring : outers) members.push_back({'w', way(ring, {}, true), "outer"});
  for (const auto& ring : inners) members.push_back({'w', way(ring, {}, true), "inner"});
  tags.emplace_back("type", "multipolygon");
  return relation(std::move(members), std::move(tags));
}

std::int64_t SyntheticMap::relation(std::vector<Member> members, Tags tags) {
  const auto id = static_cast<std::int64_t>(impl_->relations.size()) + 1;
  impl_->relations.push_back({id, std::move(members), std::move(tags)});
  return id;
}

void SyntheticMap::write(const std::filesystem::path& path, double margin_m) const {
  osmium::memory::Buffer buffer{1 << 20, osmium::memory::Buffer::auto_grow::yes};
  auto add_tags = [](osmium::builder::Builder& parent, const Tags& tags) {
    osmium::builder::TagListBuilder builder{parent};
    for (const auto& [k, v] : tags) builder.add_tag(k, v);
  };
  osmium::Box box;
  for (const auto& n : impl_->nodes) {
    osmium::builder::NodeBuilder builder{buffer};
    const osmium::Location location{n.where.lon_deg, n.where.lat_deg};
    builder.set_id(n.id).set_version(1).set_location(location);
    box.extend(location);
    add_tags(builder, n.tags);
  }
  buffer.commit();
  for (const auto& w : impl_->ways) {
    osmium::builder::WayBuilder builder{buffer};
    builder.set_id(w.id).set_version(1);
    {
      osmium::builder::WayNodeListBuilder refs{builder};
      for (auto id : w.nodes) refs.add_node_ref(id);
    }
    add_tags(builder, w.tags);
  }
  buffer.commit();
  for (const auto& r : impl_->relations) {
    osmium::builder::RelationBuilder builder{buffer};
    builder.set_id(r.id).set_version(1);
    {
      osmium::builder::RelationMemberListBuilder members{builder};
      for (const auto& m : r.members) {
        const auto type = m.type == 'n' ? osmium::item_type::node
                          : m.type == 'r' ? osmium::item_type::relation
                                          : osmium::item_type::way;
        members.add_member(type, m.ref, m.role.c_str());
      }
    }
    add_tags(builder, r.tags);
  }
  buffer.commit();

  osmium::io::Header header;
  header.set("generator", "seqloc synthetic map");
  if (box.valid()) {
    const double dlat = margin_m / 111'000.0;
    const double dlon = margin_m / (111'000.0 * std::cos(projection_.lat0_deg() * core::kDegToRad));
    header.add_box(osmium::Box{box.bottom_left().lon() - dlon, box.bottom_left().lat() - dlat,
                               box.top_right().lon() + dlon, box.top_right().lat() + dlat});
  }
  try {
    osmium::io::Writer writer{osmium::io::File{path.string()}, header, osmium::io::overwrite::allow};
    writer(std::move(buffer));
    writer.close();
  } catch (const std::exception& e) {
    throw OsmError(path.string() + ": cannot write: " + e.what());
  }
}

}  // namespace seqloc::osm
