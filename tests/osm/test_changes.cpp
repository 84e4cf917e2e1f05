// OSM change files applied to a base, against osmium-tool's `osmium apply-changes` on the same
// files (the peer: its output, as OPL, must equal ours object for object), and the refusals of
// changes that do not apply.
#include <gtest/gtest.h>

#include <filesystem>
#include <fstream>
#include <string>

#include "seqloc/osm/changes.hpp"
#include "support/test_support.hpp"

namespace seqloc::osm {
namespace {

void write(const std::filesystem::path& path, const std::string& text) { std::ofstream(path) << text; }

// Nodes 1-5, a road over 1-2-3, a track over 3-4, a relation of both; sorted as extracts are.
const char* kBase =
    "n1 v1 dV c1 t2024-01-01T00:00:00Z i1 utest T x11.0 y47.0\n"
    "n2 v1 dV c1 t2024-01-01T00:00:00Z i1 utest T x11.001 y47.0\n"
    "n3 v1 dV c1 t2024-01-01T00:00:00Z i1 utest T x11.002 y47.0\n"
    "n4 v1 dV c1 t2024-01-01T00:00:00Z i1 utest T x11.003 y47.001\n"
    "n5 v1 dV c1 t2024-01-01T00:00:00Z i1 utest Tamenity=bench x11.004 y47.002\n"
    "w10 v1 dV c1 t2024-01-01T00:00:00Z i1 utest Thighway=residential Nn1,n2,n3\n"
    "w11 v1 dV c1 t2024-01-01T00:00:00Z i1 utest Thighway=track Nn3,n4\n"
    "r20 v1 dV c1 t2024-01-01T00:00:00Z i1 utest Ttype=route Mw10@,w11@\n";

// Moves node 2 (twice: the last version counts), deletes node 5 keeping its version (as `osmium
// derive-changes` writes deletes), creates node 6 and way 12, reroutes way 11 through node 6,
// deletes relation 20.
const char* kChanges = R"(<?xml version="1.0" encoding="UTF-8"?>
<osmChange version="0.6" generator="test">
<modify>
 <node id="2" version="2" timestamp="2024-02-01T00:00:00Z" uid="1" user="test" changeset="2" lat="47.0002" lon="11.001"/>
</modify>
<modify>
 <node id="2" version="3" timestamp="2024-02-02T00:00:00Z" uid="1" user="test" changeset="3" lat="47.0004" lon="11.001"/>
</modify>
<delete>
 <node id="5" version="1" timestamp="2024-02-01T00:00:00Z" uid="1" user="test" changeset="2"/>
</delete>
<create>
 <node id="6" version="1" timestamp="2024-02-01T00:00:00Z" uid="1" user="test" changeset="2" lat="47.002" lon="11.003"/>
 <way id="12" version="1" timestamp="2024-02-01T00:00:00Z" uid="1" user="test" changeset="2">
  <nd ref="4"/><nd ref="6"/><tag k="highway" v="service"/>
 </way>
</create>
<modify>
 <way id="11" version="2" timestamp="2024-02-01T00:00:00Z" uid="1" user="test" changeset="2">
  <nd ref="3"/><nd ref="6"/><nd ref="4"/><tag k="highway" v="track"/>
 </way>
</modify>
<delete>
 <relation id="20" version="2" timestamp="2024-02-01T00:00:00Z" uid="1" user="test" changeset="2"/>
</delete>
</osmChange>
)";

std::string as_opl(const std::filesystem::path& file, const std::filesystem::path& scratch) {
  const auto out = scratch / (file.filename().string() + ".opl");
  const auto r = test::run_program(SEQLOC_OSMIUM, {"cat", "-f", "opl", "-O", "-o", out.string(), file.string()});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return test::read_file(out);
}

TEST(Changes, AppliedAsOsmiumApplyChangesAppliesThem) {
  test::ScratchDir dir;
  write(dir / "base.opl", kBase);
  write(dir / "day.osc", kChanges);
  const ChangeSummary s = apply_changes(dir / "base.opl", dir / "day.osc", dir / "new.osm.pbf");
  const auto r = test::run_program(SEQLOC_OSMIUM, {"apply-changes", "-O", "-o", (dir / "peer.osm.pbf").string(),
                                                   (dir / "base.opl").string(), (dir / "day.osc").string()});
  ASSERT_EQ(r.exit_code, 0) << r.err;
  const std::string ours = as_opl(dir / "new.osm.pbf", dir.path()), peer = as_opl(dir / "peer.osm.pbf", dir.path());
  EXPECT_EQ(ours, peer);
  EXPECT_NE(ours.find("n2 v3"), std::string::npos) << ours;
  EXPECT_EQ(ours.find("n5 "), std::string::npos) << ours;
  EXPECT_EQ(ours.find("r20 "), std::string::npos) << ours;

  using W = ChangedObject::What;
  ASSERT_EQ(s.objects.size(), 6u);
  EXPECT_EQ(s.counts[0][static_cast<int>(W::modified)], 1u);  // node 2, once however many versions
  EXPECT_EQ(s.counts[0][static_cast<int>(W::deleted)], 1u);
  EXPECT_EQ(s.counts[0][static_cast<int>(W::created)], 1u);
  EXPECT_EQ(s.counts[1][static_cast<int>(W::created)], 1u);
  EXPECT_EQ(s.counts[1][static_cast<int>(W::modified)], 1u);
  EXPECT_EQ(s.counts[2][static_cast<int>(W::deleted)], 1u);
  EXPECT_EQ(s.objects.front().type, 'n');
  EXPECT_EQ(s.objects.back().type, 'r');
}

// A base as Geofabrik's extracts are: its header says where it stands in a replication stream.
std::filesystem::path replicated_base(const test::ScratchDir& dir) {
  write(dir / "base.opl", kBase);
  const auto r = test::run_program(SEQLOC_OSMIUM,
                                   {"cat", "-O", "-o", (dir / "base.osm.pbf").string(), (dir / "base.opl").string(),
                                    "--output-header=osmosis_replication_timestamp=2024-01-31T00:00:00Z",
                                    "--output-header=osmosis_replication_sequence_number=41",
                                    "--output-header=osmosis_replication_base_url=https://example.org/region-updates"});
  EXPECT_EQ(r.exit_code, 0) << r.err;
  return dir / "base.osm.pbf";
}

// The header as osmium-tool reads it back.
std::string header_of(const std::filesystem::path& file) {
  const auto info = test::run_program(SEQLOC_OSMIUM, {"fileinfo", file.string()});
  EXPECT_EQ(info.exit_code, 0) << info.err;
  return info.out;
}

TEST(Changes, WithoutAStateTheBasesReplicationFieldsAreDroppedNotCarriedToTheNewData) {
  test::ScratchDir dir;
  const auto base = replicated_base(dir);
  write(dir / "day.osc", kChanges);
  const ChangeSummary s = apply_changes(base, dir / "day.osc", dir / "new.osm.pbf");
  EXPECT_EQ(s.replication.sequence, "");
  EXPECT_EQ(s.replication.timestamp, "");
  const std::string header = header_of(dir / "new.osm.pbf");
  EXPECT_EQ(header.find("osmosis_replication_sequence_number"), std::string::npos) << header;
  EXPECT_EQ(header.find("osmosis_replication_timestamp"), std::string::npos) << header;
  EXPECT_NE(header.find("osmosis_replication_base_url=https://example.org/region-updates"), std::string::npos)
      << header;
}

TEST(Changes, AServersStateFileGivesTheNewDataItsSequenceAndTimestamp) {
  test::ScratchDir dir;
  const auto base = replicated_base(dir);
  write(dir / "day.osc", kChanges);
  write(dir / "000042.state.txt",
        "#Thu Feb 01 00:00:00 UTC 2024\ntxnMaxQueried=1234\nsequenceNumber=42\ntimestamp=2024-02-01T00\\:00\\:00Z\n");
  const ReplicationState state = read_replication_state(dir / "000042.state.txt");
  EXPECT_EQ(state.sequence, "42");
  EXPECT_EQ(state.timestamp, "2024-02-01T00:00:00Z");
  const ChangeSummary s = apply_changes(base, dir / "day.osc", dir / "new.osm.pbf", state);
  EXPECT_EQ(s.replication.sequence, "42");
  EXPECT_EQ(s.replication.timestamp, "2024-02-01T00:00:00Z");
  const std::string header = header_of(dir / "new.osm.pbf");
  EXPECT_NE(header.find("osmosis_replication_sequence_number=42"), std::string::npos) << header;
  EXPECT_NE(header.find("osmosis_replication_timestamp=2024-02-01T00:00:00Z"), std::string::npos) << header;
}

TEST(Changes, APyosmiumSequenceFileGivesTheSequenceAlone) {
  test::ScratchDir dir;
  write(dir / "sequence.state", "42\n");
  const ReplicationState state = read_replication_state(dir / "sequence.state");
  EXPECT_EQ(state.sequence, "42");
  EXPECT_EQ(state.timestamp, "");
}

void expect_bad_state(const std::string& text, const std::string& says) {
  test::ScratchDir dir;
  write(dir / "state.txt", text);
  try {
    (void)read_replication_state(dir / "state.txt");
    ADD_FAILURE() << "read; expected a refusal saying " << says;
  } catch (const OsmInputError& e) {
    EXPECT_NE(std::string(e.what()).find((dir / "state.txt").string() + says), std::string::npos) << e.what();
  }
}

TEST(Changes, AStateFileThatIsNotOneIsRefusedNamingItsLine) {
  expect_bad_state("#comment\nsequenceNumber=4x2\n", ":2: sequenceNumber '4x2' is not a number");
  expect_bad_state("sequenceNumber=42\ntimestamp=yesterday\n", ":2: timestamp 'yesterday' is not an ISO 8601 time");
  expect_bad_state("<html>not found</html>\n", ":1: expected key=value");
  expect_bad_state("timestamp=2024-02-01T00\\:00\\:00Z\n", ": no sequence number");
  expect_bad_state("", ": no sequence number");
}

TEST(Changes, AStateThatDoesNotFollowTheBasesIsRefusedAndNothingIsWritten) {
  test::ScratchDir dir;
  const auto base = replicated_base(dir);
  write(dir / "day.osc", kChanges);
  write(dir / "old.state.txt", "sequenceNumber=41\n");
  try {
    (void)apply_changes(base, dir / "day.osc", dir / "new.osm.pbf", read_replication_state(dir / "old.state.txt"));
    ADD_FAILURE() << "applied a state at the base's own sequence";
  } catch (const OsmInputError& e) {
    EXPECT_NE(std::string(e.what()).find("old.state.txt: sequence 41 does not follow"), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "new.osm.pbf"));
}

void expect_refused(const std::string& base, const std::string& changes, const std::string& says) {
  test::ScratchDir dir;
  write(dir / "base.opl", base);
  write(dir / "bad.osc", changes);
  try {
    (void)apply_changes(dir / "base.opl", dir / "bad.osc", dir / "new.osm.pbf");
    ADD_FAILURE() << "applied; expected a refusal saying " << says;
  } catch (const OsmInputError& e) {
    EXPECT_NE(std::string(e.what()).find(says), std::string::npos) << e.what();
  }
  EXPECT_FALSE(std::filesystem::exists(dir / "new.osm.pbf"));
  for (const auto& entry : std::filesystem::directory_iterator(dir.path())) {
    EXPECT_EQ(entry.path().string().find(".partial"), std::string::npos) << entry.path();
  }
}

std::string osc(const std::string& section, const std::string& body) {
  return "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n<osmChange version=\"0.6\">\n<" + section + ">\n" + body +
         "\n</" + section + ">\n</osmChange>\n";
}

TEST(Changes, ChangesThatDoNotApplyAreRefusedAndNothingIsWritten) {
  expect_refused(kBase, osc("modify", R"(<node id="99" version="3" lat="47" lon="11"/>)"),
                 "modifies node 99 v3, which the base lacks");
  expect_refused(kBase, osc("delete", R"(<way id="77" version="2"/>)"), "deletes way 77 v2, which the base lacks");
  expect_refused(kBase, osc("modify", R"(<node id="2" version="1" lat="47" lon="11"/>)"),
                 "node 2 v1 does not follow the base's node 2 v1");
  expect_refused(kBase, osc("create", R"(<node id="3" version="1" lat="47" lon="11"/>)"),
                 "does not follow the base's node 3 v1");
  const std::string whole = kChanges;
  expect_refused(kBase, whole.substr(0, whole.size() / 2), "not a complete OSM change file");
  expect_refused("n2 v1 x11 y47\nn1 v1 x11 y47\n", osc("create", R"(<node id="9" version="1" lat="47" lon="11"/>)"),
                 "not sorted by type and id at node 1");
}

}  // namespace
}  // namespace seqloc::osm
