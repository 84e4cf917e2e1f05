#!/usr/bin/python3
"""The cluster path of docs/cluster.md run locally, every task as its own process, as the engines run it.

scripts/cluster/slurm-submit is run with a stand-in `sbatch` that runs each job at once (an array
job once per index, with Slurm's variables set); the Jobs of scripts/cluster/k8s-country.yaml are
run from the manifest itself (its command and environment, the paths mapped to a scratch folder,
once per index with JOB_COMPLETION_INDEX). Both must give the region cache of one preprocess run,
tile for tile, and the recall table of one localize run over every route.

usage: check_cluster_scripts.py SEQLOC REPOSITORY
"""
import os
import sqlite3
import subprocess
import sys
import tempfile
import unittest
from pathlib import Path

import yaml

SEQLOC = Path(sys.argv[1]).resolve() if len(sys.argv) > 1 else None
ROOT = Path(sys.argv[2]).resolve() if len(sys.argv) > 2 else None
SHARDS = 3

FAKE_SBATCH = r'''#!/usr/bin/python3
# Runs a job at once instead of queueing it: each index of an --array as its own process.
import os, subprocess, sys
args, array, cpus = sys.argv[1:], None, "1"
while args and args[0].startswith("--"):
    option = args.pop(0)
    if option.startswith("--array="):
        first, last = option.split("=", 1)[1].split("-")
        array = range(int(first), int(last) + 1)
    elif option.startswith("--cpus-per-task="):
        cpus = option.split("=", 1)[1]
counter = os.path.join(os.environ["FAKE_SBATCH_DIR"], "jobs")
job = len(open(counter).read().split()) + 1 if os.path.exists(counter) else 1
open(counter, "a").write(f"{job}\n")
for index in (array if array is not None else [None]):
    env = dict(os.environ, SLURM_CPUS_PER_TASK=cpus, SLURM_JOB_ID=str(job))
    if index is not None:
        env.update(SLURM_ARRAY_TASK_ID=str(index), SLURM_ARRAY_TASK_COUNT=str(len(array)))
    if subprocess.run(args, env=env, stdout=sys.stderr).returncode != 0:
        sys.exit(1)
print(job)
'''


def run(cmd, **kwargs):
    result = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, **kwargs)
    if result.returncode != 0:
        raise AssertionError(f"{' '.join(map(str, cmd))} failed ({result.returncode}):\n{result.stdout}\n{result.stderr}")
    return result.stdout


def tiles(cache):
    with sqlite3.connect(f"file:{cache}?mode=ro", uri=True) as db:
        return {table: db.execute(f"SELECT tile_column, tile_row, tile_data FROM {table} "
                                  "ORDER BY tile_column, tile_row").fetchall()
                for table in ("classes", "road_distance")}


class ClusterScripts(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.scratch = tempfile.TemporaryDirectory(prefix="seqloc-cluster-")
        cls.dir = Path(cls.scratch.name)
        cls.osm = ROOT / "samples" / "rural-valley.osm.pbf"
        cls.whole = cls.dir / "whole.gpkg"
        run([SEQLOC, "preprocess", cls.osm, "-o", cls.whole, "--no-progress"])
        cls.routes = cls.dir / "routes"
        run([SEQLOC, "simulate", cls.whole, "-o", cls.routes, "--routes", 4, "--frames", 8, "--seed", 5])
        run([SEQLOC, "localize", cls.whole, *sorted(cls.routes.glob("*/")), "-o", cls.dir / "whole-out",
             "--no-progress"])
        cls.table = run([SEQLOC, "evaluate", cls.dir / "whole-out"])
        cls.env = dict(os.environ, PATH=f"{SEQLOC.parent}:{os.environ['PATH']}")

    @classmethod
    def tearDownClass(cls):
        cls.scratch.cleanup()

    def check_outputs(self, work):
        self.assertEqual(tiles(work / "region.gpkg"), tiles(self.whole))
        self.assertEqual((work / "table.txt").read_text(), self.table)
        self.assertEqual(len(list((work / "shards").glob("region.*.gpkg"))), SHARDS)
        self.assertEqual(len(list((work / "out").glob("shard.*"))), SHARDS)

    def test_slurm_submit_with_every_array_task_as_its_own_process(self):
        work, bin_dir = self.dir / "slurm", self.dir / "bin"
        bin_dir.mkdir(exist_ok=True)
        sbatch = bin_dir / "sbatch"
        sbatch.write_text(FAKE_SBATCH)
        sbatch.chmod(0o755)
        env = dict(self.env, PATH=f"{bin_dir}:{self.env['PATH']}", FAKE_SBATCH_DIR=str(bin_dir), OSM=str(self.osm),
                   WORK=str(work), ROUTES=str(self.routes), SHARDS=str(SHARDS))
        ids = run([ROOT / "scripts" / "cluster" / "slurm-submit"], env=env).split()
        self.assertEqual(ids, ["1", "2", "3", "4"])
        self.check_outputs(work)

    def test_kubernetes_jobs_as_the_manifest_states_them(self):
        manifest = list(yaml.safe_load_all((ROOT / "scripts" / "cluster" / "k8s-country.yaml").read_text()))
        self.assertEqual([job["metadata"]["labels"]["stage"] for job in manifest],
                         ["preprocess", "merge", "localize", "evaluate"])
        work = self.dir / "k8s"
        mapped = {"OSM": str(self.osm), "WORK": str(work), "ROUTES": str(self.routes), "SHARDS": str(SHARDS)}
        for job in manifest:
            spec = job["spec"]
            container = spec["template"]["spec"]["containers"][0]
            env = {e["name"]: e["value"] for e in container["env"]}
            indexed = spec.get("completionMode") == "Indexed"
            if indexed:
                self.assertEqual(env["SHARDS"], str(spec["completions"]), "SHARDS must equal completions")
            env.pop("BBOX", None)  # the sample's own box
            env.update({k: v for k, v in mapped.items() if k in env})
            command = [c.replace("/opt/seqloc", str(ROOT)) for c in container["command"]]
            for index in range(SHARDS if indexed else 1):
                task_env = dict(self.env, **env)
                if indexed:
                    task_env["JOB_COMPLETION_INDEX"] = str(index)
                run(command, env=task_env)
        self.check_outputs(work)

    def test_the_update_stage_applies_each_change_file_once(self):
        """country-job update on the merged cache: two change files (osmium derive-changes of
        seeded edits) of the same name in two folders, as replication paths repeat names, applied
        in order, the new base kept, a rerun a no-op; the cache equals a rebuild of the last
        state."""
        work = self.dir / "update"
        env = dict(self.env, OSM=str(self.osm), WORK=str(work), SHARDS="1", INDEX="0")
        job = ROOT / "scripts" / "cluster" / "country-job"
        run([job, "preprocess"], env=env)
        run([job, "merge"], env=env)
        sys.path.insert(0, str(ROOT / "tests" / "support"))
        from osm_edits import edit, read_opl, write_opl
        run(["osmium", "cat", self.osm, "-f", "opl", "-o", work / "v0.opl", "-O"])
        changes = []
        for k in (1, 2):
            objects, _ = edit(read_opl(work / f"v{k - 1}.opl"), __import__("random").Random(k), roads=2, deleted=1,
                              added=1, members=0)
            write_opl(work / f"v{k}.opl", objects)
            changes.append(work / "000" / f"00{k}" / "123.osc")
            changes[-1].parent.mkdir(parents=True)
            run(["osmium", "derive-changes", work / f"v{k - 1}.opl", work / f"v{k}.opl", "-o", changes[-1], "-O"])
        # The replication server's state of the second diff, beside it as servers publish them.
        (work / "000" / "002" / "123.state.txt").write_text("sequenceNumber=2123\ntimestamp=2026-12-02T00\\:00\\:00Z\n")
        env["CHANGES"] = " ".join(map(str, changes))
        run([job, "update"], env=env)
        self.assertEqual([line.split(" ", 1)[1] for line in (work / "applied.txt").read_text().splitlines()],
                         list(map(str, changes)))
        with sqlite3.connect(f"file:{work / 'region.gpkg'}?mode=ro", uri=True) as db:
            meta = dict(db.execute("SELECT key, value FROM seqloc_metadata"))
        self.assertEqual((meta["osm_replication_sequence"], meta["osm_replication_timestamp"]),
                         ("2123", "2026-12-02T00:00:00Z"))
        self.assertEqual(run([job, "update"], env=env).count("skipped"), 2)
        rebuilt = work / "rebuilt.gpkg"
        run([SEQLOC, "preprocess", work / "base.osm.pbf", "-o", rebuilt, "--no-progress"])
        self.assertEqual(tiles(work / "region.gpkg"), tiles(rebuilt))
        self.assertNotEqual(tiles(work / "region.gpkg"), tiles(self.whole))

    def test_a_rerun_task_keeps_a_finished_shard_and_a_bad_stage_is_refused(self):
        work = self.dir / "rerun"
        env = dict(self.env, OSM=str(self.osm), WORK=str(work), SHARDS="2", INDEX="1")
        job = ROOT / "scripts" / "cluster" / "country-job"
        run([job, "preprocess"], env=env)
        shard = work / "shards" / "region.1.gpkg"
        before = shard.stat().st_mtime_ns
        self.assertIn("kept", run([job, "preprocess"], env=env))
        self.assertEqual(shard.stat().st_mtime_ns, before)
        bad = subprocess.run([str(job), "frobnicate"], env=env, capture_output=True, text=True)
        self.assertEqual(bad.returncode, 2)
        self.assertIn("usage", bad.stderr)
        missing = subprocess.run([str(job), "localize"], env=dict(env, ROUTES=""), capture_output=True, text=True)
        self.assertEqual(missing.returncode, 2)
        self.assertIn("set ROUTES", missing.stderr)


if __name__ == "__main__":
    unittest.main(argv=sys.argv[:1], verbosity=2)
