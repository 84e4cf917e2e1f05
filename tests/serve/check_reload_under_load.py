"""`seqloc serve` under wrk load while its cache file is replaced again and again (a new build
renamed over it, as `seqloc preprocess --overwrite` does). Passes when wrk saw no error and no
non-2xx answer, and every tile that checker clients fetched meanwhile is, byte for byte, the
stored tile of one of the two builds (no torn tile, no mix), with both builds served."""

import argparse
import http.client
import os
import random
import shutil
import sqlite3
import subprocess
import sys
import tempfile
import threading
import time


def stored_tiles(cache):
    db = sqlite3.connect(cache)
    rows = db.execute("SELECT tile_column, tile_row, tile_data FROM road_distance WHERE zoom_level = 0")
    return {(c, r): bytes(blob) for c, r, blob in rows}


def main():
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seqloc", required=True)
    parser.add_argument("--sample", required=True)
    parser.add_argument("--seconds", type=int, default=8)
    args = parser.parse_args()
    wrk = shutil.which("wrk")
    if not wrk:
        sys.exit("wrk is not installed (scripts/deps test installs it)")
    work = tempfile.mkdtemp(prefix="seqloc-reload-")
    try:
        builds = []
        for name, clamp in (("a", "40"), ("b", "90")):
            out = os.path.join(work, name + ".gpkg")
            subprocess.run([args.seqloc, "preprocess", args.sample, "-o", out, "--max-distance", clamp, "--no-progress"],
                           check=True, stdout=subprocess.DEVNULL)
            builds.append(stored_tiles(out))
        keys = sorted(builds[0])
        differing = [k for k in keys if builds[0][k] != builds[1][k]]
        assert differing, "the two builds must differ"
        served = os.path.join(work, "valley.gpkg")
        shutil.copy(os.path.join(work, "a.gpkg"), served)

        server = subprocess.Popen([args.seqloc, "serve", served, "--port", "0", "--reload-check", "0.05"],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = server.stdout.readline()
        assert line.startswith("seqloc serve: http://"), line
        host, port = line.split()[2].split("//")[1].rstrip("/").rsplit(":", 1)
        paths = [f"/regions/valley/road_distance/{c}/{r}.png" for c, r in differing]
        with open(os.path.join(work, "tiles.lua"), "w") as f:
            f.write("paths = {" + ",".join(f'"{p}"' for p in paths) + "}\n")
            f.write("i = 0\nrequest = function()\n  i = i % #paths + 1\n  return wrk.format('GET', paths[i])\nend\n")

        stop = threading.Event()
        replacements = [0]
        seen = {0: 0, 1: 0}
        problems = []

        def replace_forever():
            which = 1
            while not stop.is_set():
                incoming = os.path.join(work, "incoming.gpkg")
                shutil.copy(os.path.join(work, "ab"[which] + ".gpkg"), incoming)
                os.replace(incoming, served)
                replacements[0] += 1
                which = 1 - which
                time.sleep(0.2)

        def check_forever(seed):
            rng = random.Random(seed)
            conn = http.client.HTTPConnection(host, int(port), timeout=10)
            while not stop.is_set():
                c, r = rng.choice(differing)
                conn.request("GET", f"/regions/valley/road_distance/{c}/{r}.png")
                response = conn.getresponse()
                body = response.read()
                if response.status != 200:
                    problems.append(f"tile {c},{r}: HTTP {response.status}: {body[:200]!r}")
                elif body == builds[0][(c, r)]:
                    seen[0] += 1
                elif body == builds[1][(c, r)]:
                    seen[1] += 1
                else:
                    problems.append(f"tile {c},{r}: {len(body)} bytes that are neither build's tile")

        threads = [threading.Thread(target=replace_forever)] + [
            threading.Thread(target=check_forever, args=(s,)) for s in range(2)]
        for t in threads:
            t.start()
        result = subprocess.run([wrk, "-t2", "-c16", f"-d{args.seconds}s", "-s", os.path.join(work, "tiles.lua"),
                                 f"http://{host}:{port}"], capture_output=True, text=True)
        stop.set()
        for t in threads:
            t.join()
        server.terminate()
        _, err = server.communicate(timeout=30)
        print(result.stdout)
        print(f"replacements: {replacements[0]}, checked tiles: build a {seen[0]}, build b {seen[1]}")
        reloads = err.count("reloaded")
        print(f"server reloads: {reloads}")
        failures = list(problems[:10])
        if result.returncode != 0:
            failures.append(f"wrk failed: {result.stderr}")
        for marker in ("Non-2xx or 3xx responses", "Socket errors"):
            if marker in result.stdout:
                failures.append(f"wrk reported: {marker}")
        if "Requests/sec" not in result.stdout:
            failures.append("wrk made no requests")
        if seen[0] == 0 or seen[1] == 0 or reloads < 2:
            failures.append("the replacement was not served: the test proved nothing")
        if "refused" in err or "not served" in err:
            failures.append("the server refused a complete cache: " + err[-500:])
        if failures:
            print("FAILED:\n  " + "\n  ".join(failures))
            sys.exit(1)
        print("OK")
    finally:
        shutil.rmtree(work, ignore_errors=True)


if __name__ == "__main__":
    main()
