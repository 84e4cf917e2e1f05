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

/// Where the data stands in a replication stream: the sequence number of the last diff it holds
/// and that diff's timestamp (ISO 8601, UTC). Either may be empty: not known.
struct ReplicationState {
  std::string sequence, timestamp;
  std::string source;  ///< the file it was read from, named in errors (empty: given directly)
};

/// Reads the replication state of a change file from `path`, in either form tools write it:
/// - a replication server's state file (`NNN.state.txt` beside `NNN.osc.gz`, or `state.txt`):
///   Java properties with `sequenceNumber=` and `timestamp=` (colons escaped as `\:`), other keys
///   and `#` comments ignored;
/// - a file holding just the sequence number, as `pyosmium-get-changes -f` writes it.
/// Throws OsmInputError naming the file and line of anything else.
[[nodiscard]] ReplicationState read_replication_state(const std::filesystem::path& path);

struct ChangeSummary {
  std::vector<ChangedObject> objects;  ///< in type and id order, one entry per object
  /// created, modified, deleted, for nodes, ways and relations: counts[type][what].
  std::array<std::array<std::size_t, 3>, 3> counts{};
  /// The new state's replication sequence and timestamp: the ones passed to apply_changes. OSM
  /// change files do not carry them, and the base's describe the old state, so without a state
  /// they are empty.
  ReplicationState replication;
};

/// Reads `changes` (several versions of an object: the last one counts) and checks it against
/// `base`, which must be sorted by type and id as OSM extracts are:
/// - a modify or delete (a version above 1) of an object the base lacks is refused;
/// - a create (version 1) of an object the base has is refused;
/// - a version at or below the base's is refused (versions going backwards);
/// - a change file that is truncated or not OSM XML is refused.
/// - a `state` whose sequence number is not above the base header's is refused (a state file that
///   does not belong to this change).
/// Then writes the new state to `output` (.osm.pbf; written whole or not at all) with the base's
/// header, its replication sequence and timestamp replaced by `state`'s: dropped where `state`
/// leaves them empty, so that no tool takes the old state's for the new data's (the replication
/// server's URL is kept). Throws OsmInputError naming the file and the object.
ChangeSummary apply_changes(const std::filesystem::path& base, const std::filesystem::path& changes,
                            const std::filesystem::path& output, const ReplicationState& state = {});

}  // namespace seqloc::osm
