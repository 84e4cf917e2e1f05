#pragma once
// OSM change files (the XML change format, .osc[.gz|.bz2], as replication diffs and `osmium
// derive-changes` write them) applied to a base file: the new state of the data, written as
// `osmium apply-changes` writes it, with every change checked against the base first.

#include <array>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "seqloc/osm/errors.hpp"

namespace seqloc::osm {

/// An object a change file touches: its type ('n', 'w' or 'r'), id and what happened to it.
struct ChangedObject {
  enum class What { created, modified, deleted };
  char type = 'n';
  std::int64_t id = 0;
  What what = What::modified;
};

struct ChangeSummary {
  std::vector<ChangedObject> objects;  ///< in type and id order, one entry per object
  /// created, modified, deleted, for nodes, ways and relations: counts[type][what].
  std::array<std::array<std::size_t, 3>, 3> counts{};
  /// The change file's replication timestamp and sequence number where its header has them, else
  /// the base's (empty: neither has one).
  std::string replication_timestamp, replication_sequence;
};

/// Reads `changes` (several versions of an object: the last one counts) and checks it against
/// `base`, which must be sorted by type and id as OSM extracts are:
/// - a modify or delete (a version above 1) of an object the base lacks is refused;
/// - a create (version 1) of an object the base has is refused;
/// - a version at or below the base's is refused (versions going backwards);
/// - a change file that is truncated or not OSM XML is refused.
/// Then writes the new state to `output` (.osm.pbf; written whole or not at all), the base's
/// header kept with the replication fields updated. Throws OsmInputError naming the file and the
/// object.
ChangeSummary apply_changes(const std::filesystem::path& base, const std::filesystem::path& changes,
                            const std::filesystem::path& output);

}  // namespace seqloc::osm
