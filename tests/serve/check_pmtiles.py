"""`seqloc export --format pmtiles` read back by the npm registry's PMTiles decoder
(tests/serve/pmtiles/read_archive.mjs): every tile `seqloc serve` answers for the region is in the
archive with the server's bytes, and no other. Two archives: the sample region's classes as
pictures, and a real extract's (Monaco) road prior as data with a root budget small enough that
the writer makes leaf directories. Then the command's refusals: a zoom the region does not serve
and an existing output without --overwrite exit 2 and write nothing."""

import argparse
import os
import subprocess
import sys
import tempfile


def run(*cmd, expect=0):
    r = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=600)
    if r.returncode != expect:
        sys.exit(f"{' '.join(map(str, cmd[:4]))}: exit {r.returncode}, expected {expect}\n{r.stdout}\n{r.stderr}")
    return r


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--seqloc", required=True)
    p.add_argument("--sample", required=True, help="the sample region's .osm.pbf")
    p.add_argument("--extract", required=True, help="a real OSM extract (.osm.pbf)")
    p.add_argument("--reader", required=True, help="read_archive.mjs")
    a = p.parse_args()
    with tempfile.TemporaryDirectory() as d:
        sample, real = os.path.join(d, "sample.gpkg"), os.path.join(d, "monaco.gpkg")
        run(a.seqloc, "preprocess", a.sample, "-o", sample, "--no-progress")
        run(a.seqloc, "preprocess", a.extract, "-o", real, "--no-progress")
        archives = [(os.path.join(d, "sample.pmtiles"), "sample", "classes", "color", []),
                    (os.path.join(d, "monaco.pmtiles"), "monaco", "road_prior", "data",
                     ["--zoom", "15-17", "--root-bytes", "400", "--leaf-entries", "32"])]
        for path, region, layer, style, extra in archives:
            cache = sample if region == "sample" else real
            run(a.seqloc, "export", cache, "--layer", layer, "--style", style, "-o", path, "--no-progress", *extra)
            if os.path.exists(path + ".partial"):
                sys.exit(f"{path}.partial left behind")
        server = subprocess.Popen([a.seqloc, "serve", sample, real, "--port", "0"], stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True)
        failed = 0
        try:
            base = server.stdout.readline().split()[2]
            for path, region, layer, style, options in archives:
                zooms = options[options.index("--zoom") + 1:][:1] if "--zoom" in options else []
                r = subprocess.run(["node", a.reader, path, base, region, layer, style] + zooms, capture_output=True,
                                   text=True, timeout=600)
                sys.stdout.write(r.stdout)
                sys.stderr.write(r.stderr)
                failed += r.returncode != 0
        finally:
            server.terminate()
            server.wait(timeout=20)
        # Refusals: one line, exit 2, nothing written.
        bad = os.path.join(d, "bad.pmtiles")
        r = run(a.seqloc, "export", sample, "--zoom", "2-30", "-o", bad, expect=2)
        if os.path.exists(bad) or os.path.exists(bad + ".partial") or len(r.stderr.strip().splitlines()) != 1:
            sys.exit(f"a bad zoom: {r.stderr!r}, output left: {os.path.exists(bad)}")
        r = run(a.seqloc, "export", sample, "--layer", "roads", "-o", bad, expect=2)
        r = run(a.seqloc, "export", sample, "-o", archives[0][0], expect=2)  # exists, no --overwrite
        if failed:
            sys.exit(f"{failed} archive(s) not read back as served")
        print("5 passed, 0 failed")


if __name__ == "__main__":
    main()
