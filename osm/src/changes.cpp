#include "seqloc/osm/changes.hpp"

#include <unistd.h>

#include <algorithm>
#include <fstream>
#include <optional>
#include <osmium/io/any_input.hpp>
#include <osmium/io/any_output.hpp>
#include <osmium/io/input_iterator.hpp>
#include <osmium/memory/buffer.hpp>
#include <osmium/osm/object.hpp>
#include <osmium/osm/object_comparisons.hpp>
#include <osmium/osm/timestamp.hpp>
#include <string_view>
#include <tuple>
#include <utility>

#include "seqloc/core/files.hpp"

namespace seqloc::osm {
namespace {

// An object's place in a sorted OSM file: nodes, then ways, then relations, each by id.
struct Key {
  int type = 0;
  std::int64_t id = 0;
  friend bool operator<(const Key& a, const Key& b) { return std::tie(a.type, a.id) < std::tie(b.type, b.id); }
  friend bool operator==(const Key& a, const Key& b) { return a.type == b.type && a.id == b.id; }
};

Key key_of(const osmium::OSMObject& o) { return {static_cast<int>(o.type()), o.id()}; }

char type_char(const osmium::OSMObject& o) { return osmium::item_type_to_char(o.type()); }

std::string describe(const osmium::OSMObject& o) {
  return std::string(osmium::item_type_to_name(o.type())) + " " + std::to_string(o.id()) + " v" +
         std::to_string(o.version());
}

std::size_t type_index(const osmium::OSMObject& o) {
  return o.type() == osmium::item_type::node ? 0 : o.type() == osmium::item_type::way ? 1 : 2;
}

// The change file's objects, the last version of each, in type and id order.
class ChangeList {
 public:
  explicit ChangeList(const std::filesystem::path& path) {
    osmium::io::Reader reader{osmium::io::File{path.string()}, osmium::osm_entity_bits::object};
    while (osmium::memory::Buffer b = reader.read()) buffers_.push_back(std::move(b));
    reader.close();
    for (auto& b : buffers_) {
      for (const auto& o : b.select<osmium::OSMObject>()) objects_.push_back(&o);
    }
    std::stable_sort(objects_.begin(), objects_.end(),
                     [](const auto* a, const auto* b) { return osmium::object_order_type_id_version{}(*a, *b); });
    // The last version of each object counts (a diff may carry several).
    std::vector<const osmium::OSMObject*> last;
    for (const auto* o : objects_) {
      if (!last.empty() && key_of(*last.back()) == key_of(*o)) {
        last.back() = o;
      } else {
        last.push_back(o);
      }
    }
    objects_ = std::move(last);
  }
  [[nodiscard]] const osmium::OSMObject* peek() const { return next_ < objects_.size() ? objects_[next_] : nullptr; }
  void pop() { ++next_; }

 private:
  std::vector<osmium::memory::Buffer> buffers_;
  std::vector<const osmium::OSMObject*> objects_;
  std::size_t next_ = 0;
};

class Merge {
 public:
  Merge(const std::filesystem::path& changes_path, ChangeSummary& summary, osmium::io::Writer& writer)
      : changes_path_(changes_path.string()), summary_(summary), writer_(writer) {}

  // A change for an object the base lacks: only a creation applies.
  void create(const osmium::OSMObject& c) {
    if (!c.visible() || c.version() > 1) {
      throw OsmInputError(changes_path_ + ": " + (c.visible() ? "modifies " : "deletes ") + describe(c) +
                          ", which the base lacks: the change file does not apply to this base");
    }
    record(c, ChangedObject::What::created);
    writer_(c);
  }
  // A change for an object the base has: a newer version (a delete may keep the version, as
  // `osmium derive-changes` writes them), or nothing applies.
  void replace(const osmium::OSMObject& base, const osmium::OSMObject& c) {
    const bool newer = c.visible() ? c.version() > base.version() : c.version() >= base.version();
    if (!newer || c.version() == 0) {
      throw OsmInputError(changes_path_ + ": " + describe(c) + " does not follow the base's " + describe(base) +
                          " (versions going backwards: is the base older than the change file?)");
    }
    record(c, c.visible() ? ChangedObject::What::modified : ChangedObject::What::deleted);
    if (c.visible()) writer_(c);
  }
  void keep(const osmium::OSMObject& o) { writer_(o); }

 private:
  void record(const osmium::OSMObject& c, ChangedObject::What what) {
    summary_.objects.push_back({type_char(c), c.id(), what});
    ++summary_.counts[type_index(c)][static_cast<std::size_t>(what)];
  }
  std::string changes_path_;
  ChangeSummary& summary_;
  osmium::io::Writer& writer_;
};

void merge(const std::filesystem::path& base, ChangeList& changes, Merge& merge, osmium::io::Reader& reader) {
  std::optional<Key> previous;
  for (const auto& o : osmium::io::make_input_iterator_range<osmium::OSMObject>(reader)) {
    const Key k = key_of(o);
    if (previous && !(*previous < k)) {
      throw OsmInputError(base.string() + ": not sorted by type and id at " + describe(o) +
                          " (sort it with `osmium sort`)");
    }
    previous = k;
    while (changes.peek() && key_of(*changes.peek()) < k) {
      merge.create(*changes.peek());
      changes.pop();
    }
    if (changes.peek() && key_of(*changes.peek()) == k) {
      merge.replace(o, *changes.peek());
      changes.pop();
    } else {
      merge.keep(o);
    }
  }
  for (; changes.peek(); changes.pop()) merge.create(*changes.peek());
}

constexpr const char* kSequenceField = "osmosis_replication_sequence_number";
constexpr const char* kTimestampField = "osmosis_replication_timestamp";

bool all_digits(std::string_view s) {
  return !s.empty() && s.size() <= 18 && std::all_of(s.begin(), s.end(), [](char c) { return c >= '0' && c <= '9'; });
}

// A Java properties value: `\:` and the like stand for the character escaped.
std::string unescape(std::string_view v) {
  std::string out;
  for (std::size_t i = 0; i < v.size(); ++i) {
    if (v[i] == '\\' && i + 1 < v.size()) ++i;
    out += v[i];
  }
  return out;
}

std::string trimmed(std::string_view s) {
  const auto first = s.find_first_not_of(" \t\r");
  if (first == std::string_view::npos) return {};
  return std::string(s.substr(first, s.find_last_not_of(" \t\r") - first + 1));
}

// One line of a state file, into `state`; throws naming `where` (file:line).
void read_state_line(const std::string& line, const std::string& where, ReplicationState& state) {
  if (all_digits(line)) {  // pyosmium-get-changes -f: the sequence number alone
    state.sequence = line;
    return;
  }
  const auto eq = line.find_first_of("=:");
  if (eq == std::string::npos) throw OsmInputError(where + ": expected key=value or a sequence number");
  const std::string key = trimmed(line.substr(0, eq));
  const std::string value = unescape(trimmed(line.substr(eq + 1)));
  if (key == "sequenceNumber") {
    if (!all_digits(value)) throw OsmInputError(where + ": sequenceNumber '" + value + "' is not a number");
    state.sequence = value;
  } else if (key == "timestamp") {
    try {
      state.timestamp = osmium::Timestamp(value.c_str()).to_iso();
    } catch (const std::exception&) {
      throw OsmInputError(where + ": timestamp '" + value + "' is not an ISO 8601 time (2024-01-31T00:00:00Z)");
    }
  }
}

// The base's header made the new data's: its replication sequence and timestamp describe the old
// state, so `state`'s replace them; an empty field is not written, so an unknown one is dropped.
void set_replication(const std::filesystem::path& base, const ReplicationState& state, osmium::io::Header& header) {
  const std::string base_sequence = header.get(kSequenceField);
  if (!state.sequence.empty() && !all_digits(state.sequence)) {
    throw OsmInputError("replication sequence '" + state.sequence + "' is not a number");
  }
  if (!state.sequence.empty() && all_digits(base_sequence) && std::stoll(state.sequence) <= std::stoll(base_sequence)) {
    throw OsmInputError((state.source.empty() ? std::string("the replication state") : state.source) + ": sequence " +
                        state.sequence + " does not follow " + base.string() + "'s " + base_sequence +
                        " (the state of another change file?)");
  }
  header.set(kSequenceField, state.sequence);
  header.set(kTimestampField, state.timestamp);
  header.set("timestamp", state.timestamp);
}

}  // namespace

ReplicationState read_replication_state(const std::filesystem::path& path) {
  std::ifstream in(path);
  if (!in) throw OsmInputError(path.string() + ": cannot open the replication state file");
  ReplicationState state;
  state.source = path.string();
  std::string line;
  for (int number = 1; std::getline(in, line); ++number) {
    line = trimmed(line);
    if (line.empty() || line.front() == '#' || line.front() == '!') continue;
    read_state_line(line, path.string() + ":" + std::to_string(number), state);
  }
  if (state.sequence.empty()) {
    throw OsmInputError(path.string() +
                        ": no sequence number (a state.txt has sequenceNumber=N; a sequence "
                        "file holds N alone)");
  }
  return state;
}

ChangeSummary apply_changes(const std::filesystem::path& base, const std::filesystem::path& changes,
                            const std::filesystem::path& output, const ReplicationState& state) {
  for (const auto& p : {base, changes}) {
    std::error_code ec;
    if (!std::filesystem::is_regular_file(p, ec)) throw OsmInputError(p.string() + ": no such file");
    if (std::filesystem::file_size(p, ec) == 0) throw OsmInputError(p.string() + ": empty file, no OSM data");
  }
  std::optional<ChangeList> list;
  try {
    list.emplace(changes);
  } catch (const std::exception& e) {
    throw OsmInputError(changes.string() + ": not a complete OSM change file: " + e.what());
  }
  ChangeSummary summary;
  const std::filesystem::path partial = output.string() + ".partial-" + std::to_string(::getpid());
  try {
    osmium::io::Reader reader{osmium::io::File{base.string()}, osmium::osm_entity_bits::object};
    osmium::io::Header header = reader.header();
    header.set("generator", "seqloc");
    set_replication(base, state, header);
    summary.replication = state;  // what set_replication wrote into the header
    osmium::io::Writer writer{osmium::io::File{partial.string(), "pbf"}, header, osmium::io::overwrite::allow};
    Merge m(changes, summary, writer);
    merge(base, *list, m, reader);
    writer.close();
    reader.close();
    core::commit_file(partial, output);
  } catch (const OsmError&) {
    std::error_code ignored;
    std::filesystem::remove(partial, ignored);
    throw;
  } catch (const std::exception& e) {
    std::error_code ignored;
    std::filesystem::remove(partial, ignored);
    throw OsmInputError(base.string() + ": cannot apply " + changes.string() + ": " + e.what());
  }
  return summary;
}

}  // namespace seqloc::osm
