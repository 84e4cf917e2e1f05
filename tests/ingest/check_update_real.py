"""`seqloc update` on a real extract with generated edits, against a rebuild (issue 44).

The edits are made on the extract's objects (seeded): road nodes moved, buildings deleted, a
building added, a node of a multipolygon's member way moved. osmium-tool writes the change file
(`osmium derive-changes`) and the new data (`osmium apply-changes`); `seqloc preprocess` of that
new data over the cache's own box is the reference. The updated cache must equal it tile for tile
in both layers and road for road, having re-rendered fewer tiles than the region has. Bad input
(a base the cache was not built from, a change file that does not apply) must exit 1 with the
cache untouched."""

import argparse
import http.client
import os
import random
import re
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import time
import unittest

sys.path.insert(0, os.path.join(os.path.dirname(os.path.abspath(__file__)), "..", "support"))
from osm_edits import edit, field, read_opl, write_opl  # noqa: E402

ARGS = None


def run(*cmd, expect=0):
    r = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=900)
    if r.returncode != expect:
        raise AssertionError(f"{cmd[:3]}: exit {r.returncode}, expected {expect}\n{r.stdout}\n{r.stderr}")
    return r


def tiles(path):
    db = sqlite3.connect(path)
    out = {}
    for table in ("classes", "road_distance"):
        for col, row, data in db.execute(f"SELECT tile_column, tile_row, tile_data FROM {table}"):
            out[(table, col, row)] = bytes(data)
    roads = list(db.execute("SELECT geom, osm_id, highway FROM roads ORDER BY fid"))
    meta = dict(db.execute("SELECT key, value FROM seqloc_metadata"))
    db.close()
    return out, roads, meta


class UpdateRealExtract(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory()
        d = cls.d = cls.tmp.name
        cls.old = ARGS.extract
        run("osmium", "cat", cls.old, "-f", "opl", "-o", os.path.join(d, "old.opl"), "-O")
        objects, cls.moved = edit(read_opl(os.path.join(d, "old.opl")), random.Random(44), roads=5, deleted=2, added=1,
                                  members=1)
        write_opl(os.path.join(d, "new.opl"), objects)
        cls.changes = os.path.join(d, "day.osc")
        run("osmium", "derive-changes", os.path.join(d, "old.opl"), os.path.join(d, "new.opl"), "-o", cls.changes, "-O")
        cls.cache = os.path.join(d, "old.gpkg")
        run(ARGS.seqloc, "preprocess", cls.old, "-o", cls.cache, "--no-progress")

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    def test_the_update_equals_a_rebuild_of_the_new_data(self):
        d = self.d
        updated = os.path.join(d, "updated.gpkg")
        r = run(ARGS.seqloc, "update", self.cache, "--base", self.old, "--changes", self.changes, "-o", updated,
                "--no-progress")
        m = re.search(r"(\d+) of (\d+) tiles re-rendered", r.stdout)
        self.assertIsNotNone(m, r.stdout)
        rendered, total = int(m.group(1)), int(m.group(2))
        # The reference: osmium's new data, preprocessed over the cache's own box.
        new = os.path.join(d, "new.osm.pbf")
        run("osmium", "apply-changes", self.old, self.changes, "-o", new, "-O")
        _, _, meta = tiles(self.cache)
        bbox = ",".join(meta[k] for k in ("bbox_min_lon", "bbox_min_lat", "bbox_max_lon", "bbox_max_lat"))
        rebuilt = os.path.join(d, "rebuilt.gpkg")
        run(ARGS.seqloc, "preprocess", new, "-o", rebuilt, "--bbox", bbox, "--no-progress")
        old_tiles, _, _ = tiles(self.cache)
        got, got_roads, got_meta = tiles(updated)
        want, want_roads, _ = tiles(rebuilt)
        self.assertEqual(set(got), set(want))
        differing = [k for k in want if got[k] != want[k]]
        self.assertEqual(differing, [])
        self.assertEqual(got_roads, want_roads)
        changed = {(c, r) for (_, c, r) in want if old_tiles.get((_, c, r)) != want[(_, c, r)]}
        self.assertGreater(len(changed), 0)
        self.assertLessEqual(len(changed), rendered)
        self.assertLess(rendered, total)
        self.assertEqual(got_meta["changes_applied"], "day.osc")
        # No --state: the base's replication fields are the old state's, so none are recorded.
        self.assertEqual((got_meta["osm_replication_sequence"], got_meta["osm_replication_timestamp"]), ("", ""))
        self.assertIn("replication state: not known", r.stdout)
        print(f"\n{self.moved} nodes moved, 2 buildings deleted, 1 added: {len(changed)} tiles changed, "
              f"{rendered} of {total} re-rendered", file=sys.stderr)

    def test_a_state_file_is_recorded_in_the_cache_and_the_new_base(self):
        """preprocess records the base header's replication state (read back by osmium-tool); update
        with the change's state.txt records the new one in the cache and in --new-base's header, the
        replication server's URL kept, so that the next diff can be fetched from it."""
        d = self.d

        def header(path, option):
            r = run("osmium", "fileinfo", "-g", f"header.option.{option}", path)
            return r.stdout.strip()

        sequence = header(self.old, "osmosis_replication_sequence_number")
        url = header(self.old, "osmosis_replication_base_url")
        self.assertTrue(sequence.isdigit() and url, (sequence, url))
        _, _, old_meta = tiles(self.cache)
        self.assertEqual(old_meta["osm_replication_sequence"], sequence)
        self.assertEqual(old_meta["osm_replication_timestamp"], header(self.old, "osmosis_replication_timestamp"))
        state = os.path.join(d, "next.state.txt")
        with open(state, "w") as f:
            f.write(f"#Wed Apr 21 21:21:46 UTC 2021\nsequenceNumber={int(sequence) + 1}\n"
                    "timestamp=2021-04-21T21\\:21\\:46Z\n")
        updated, new_base = os.path.join(d, "stated.gpkg"), os.path.join(d, "next.osm.pbf")
        r = run(ARGS.seqloc, "update", self.cache, "--base", self.old, "--changes", self.changes, "--state", state,
                "-o", updated, "--new-base", new_base, "--no-progress")
        self.assertIn(f"replication state: sequence {int(sequence) + 1}, timestamp 2021-04-21T21:21:46Z", r.stdout)
        _, _, meta = tiles(updated)
        self.assertEqual(meta["osm_replication_sequence"], str(int(sequence) + 1))
        self.assertEqual(meta["osm_replication_timestamp"], "2021-04-21T21:21:46Z")
        self.assertEqual(header(new_base, "osmosis_replication_sequence_number"), str(int(sequence) + 1))
        self.assertEqual(header(new_base, "osmosis_replication_timestamp"), "2021-04-21T21:21:46Z")
        self.assertEqual(header(new_base, "osmosis_replication_base_url"), url)

    def test_serve_picks_up_an_update_in_place(self):
        """`seqloc serve` keeps answering while the cache it serves is updated in place, and then
        serves the updated tiles."""
        d = self.d
        served = os.path.join(d, "served.gpkg")
        shutil.copy(self.cache, served)
        server = subprocess.Popen([str(ARGS.seqloc), "serve", served, "--port", "0", "--reload-check", "0.05"],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        try:
            line = server.stdout.readline()
            self.assertTrue(line.startswith("seqloc serve: http://"), line)
            host, port = line.split()[2].split("//")[1].rstrip("/").split(":")

            def get(col, row):
                conn = http.client.HTTPConnection(host, int(port), timeout=10)
                conn.request("GET", f"/regions/served/road_distance/{col}/{row}.png")
                r = conn.getresponse()
                body = r.read()
                conn.close()
                self.assertEqual(r.status, 200)
                return body

            before, _, _ = tiles(served)
            run(ARGS.seqloc, "update", served, "--base", self.old, "--changes", self.changes, "--no-progress")
            after, _, _ = tiles(served)
            changed = [(c, r) for (t, c, r) in after if t == "road_distance" and before[(t, c, r)] != after[(t, c, r)]]
            self.assertGreater(len(changed), 0)
            deadline = time.monotonic() + 15
            while any(get(c, r) != after[("road_distance", c, r)] for c, r in changed):
                self.assertLess(time.monotonic(), deadline, "the server still serves the old tiles")
                time.sleep(0.1)
        finally:
            server.terminate()
            server.communicate(timeout=30)
        self.assertEqual(server.returncode, 0)

    def test_bad_input_exits_1_and_leaves_the_cache(self):
        d = self.d
        with open(self.cache, "rb") as f:
            before = f.read()
        truncated = os.path.join(d, "cut.osc")
        with open(self.changes) as f, open(truncated, "w") as g:
            text = f.read()
            g.write(text[: len(text) // 2])
        # A node of the base at its own version (versions going backwards), and one it lacks.
        first = next(o for o in read_opl(os.path.join(d, "old.opl")) if o[0][0] == "n")
        backwards, missing = os.path.join(d, "backwards.osc"), os.path.join(d, "missing.osc")
        for path, node_id, version in ((backwards, first[0][1:], field(first, "v")), (missing, "999999999999", "5")):
            with open(path, "w") as g:
                g.write(f'<?xml version="1.0"?>\n<osmChange version="0.6"><modify><node id="{node_id}" '
                        f'version="{version}" lat="43.7" lon="7.4"/></modify></osmChange>\n')
        # The state of an older diff: its sequence is the base's own.
        stale = os.path.join(d, "stale.state.txt")
        with open(stale, "w") as f:
            f.write(run("osmium", "fileinfo", "-g", "header.option.osmosis_replication_sequence_number",
                        self.old).stdout)
        for base, changes, extra, says in ((ARGS.other, self.changes, [], "not the OSM file"),
                                           (self.old, truncated, [], "not a complete OSM change file"),
                                           (self.old, backwards, [], "versions going backwards"),
                                           (self.old, missing, [], "which the base lacks"),
                                           (self.old, self.changes, ["--state", stale], "does not follow")):
            r = run(ARGS.seqloc, "update", self.cache, "--base", base, "--changes", changes, *extra, "--no-progress",
                    expect=1)
            self.assertIn(says, r.stderr)
            self.assertEqual(len(r.stderr.strip().splitlines()), 1, r.stderr)
            with open(self.cache, "rb") as f:
                self.assertEqual(f.read(), before)
            self.assertEqual([n for n in os.listdir(d) if ".partial" in n or ".new-" in n], [])
        # A cache of another format version: refused as it is, not rebuilt or changed.
        other = os.path.join(d, "v2.gpkg")
        shutil.copy(self.cache, other)
        db = sqlite3.connect(other)
        db.execute("UPDATE seqloc_metadata SET value = '2' WHERE key = 'format_version'")
        db.commit()
        db.close()
        with open(other, "rb") as f:
            v2 = f.read()
        r = run(ARGS.seqloc, "update", other, "--base", self.old, "--changes", self.changes, "--no-progress", expect=1)
        self.assertIn("format version 2", r.stderr)
        with open(other, "rb") as f:
            self.assertEqual(f.read(), v2)


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("--seqloc", required=True)
    parser.add_argument("--extract", required=True)
    parser.add_argument("--other", required=True, help="another OSM file, not the cache's base")
    ARGS, rest = parser.parse_known_args()
    unittest.main(argv=[sys.argv[0]] + rest)
