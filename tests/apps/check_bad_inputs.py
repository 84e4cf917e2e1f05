"""Every bad input of docs/bad-input.md, tried for real: each case runs the seqloc binary (or asks
the server), checks the exit code (or HTTP status), that the message names the file, line or tile,
and that the previous good output is still there, unchanged. `--markdown` prints the table of
docs/bad-input.md from the same runs, so the table cannot drift from what the program does."""

import argparse
import hashlib
import json
import os
import shutil
import sqlite3
import struct
import subprocess
import sys
import tempfile
import urllib.error
import urllib.request

import numpy as np

ARGS = None
ROWS = []
FAILURES = []


def run(*args):
    return subprocess.run([ARGS.seqloc, *map(str, args)], capture_output=True, text=True, errors="replace")


def digest(path):
    if os.path.isdir(path):
        h = hashlib.sha256()
        for root, _, files in sorted(os.walk(path)):
            for name in sorted(files):
                with open(os.path.join(root, name), "rb") as f:
                    h.update(name.encode() + f.read())
        return h.hexdigest()
    with open(path, "rb") as f:
        return hashlib.sha256(f.read()).hexdigest()


def case(what, command, result, expect_exit, fragments, kept=None, before=None, kept_text=""):
    message = (result.stderr.strip().splitlines() or [""])[-1]
    ok = result.returncode == expect_exit and all(f in message for f in fragments)
    if kept is not None:
        still = os.path.exists(kept) and digest(kept) == before
        ok = ok and still
        kept_text = kept_text or ("the previous output, unchanged" if still else "NOT KEPT")
    if not ok:
        FAILURES.append(f"{what}: exit {result.returncode} (wanted {expect_exit}), message {message!r}, "
                        f"wanted {fragments}")
    ROWS.append((what, command, message, str(result.returncode), kept_text or "nothing is written"))


def http_case(what, base, path, status, fragment):
    try:
        with urllib.request.urlopen(base + path) as r:
            got, body = r.status, r.read().decode()
    except urllib.error.HTTPError as e:
        got, body = e.code, e.read().decode()
    message = json.loads(body)["error"]["message"] if body.startswith("{") else body
    if got != status or fragment not in message:
        FAILURES.append(f"{what}: HTTP {got} (wanted {status}), {message!r}")
    ROWS.append((what, f"GET {path[:60]}", message, f"HTTP {got}", "the server keeps serving"))


def npy(path, array, header_shape=None):
    np.save(path, array)
    if header_shape is not None:  # rewrite the header's shape, keeping the data
        with open(path, "rb") as f:
            data = f.read()
        text = data[10:10 + struct.unpack("<H", data[8:10])[0]].decode()
        text = text.replace(str(array.shape), header_shape)
        text = text.rstrip().ljust(len(data[10:10 + struct.unpack("<H", data[8:10])[0]]) - 1) + "\n"
        with open(path, "wb") as f:
            f.write(data[:10] + text.encode() + data[10 + len(text):])


def main():
    global ARGS
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--seqloc", required=True)
    parser.add_argument("--sample", required=True)
    parser.add_argument("--markdown", action="store_true")
    ARGS = parser.parse_args()
    w = tempfile.mkdtemp(prefix="seqloc-bad-")
    try:
        cache = os.path.join(w, "valley.gpkg")
        assert run("preprocess", ARGS.sample, "-o", cache, "--no-progress").returncode == 0
        before_cache = digest(cache)
        raw = open(ARGS.sample, "rb").read()

        def bad_pbf(name, data):
            path = os.path.join(w, name)
            with open(path, "wb") as f:
                f.write(data)
            return path

        for what, data, fragments in [
            ("corrupt .osm.pbf (random bytes)", os.urandom(4096), ["corrupt.osm.pbf", "cannot read OSM data"]),
            ("truncated .osm.pbf (first half)", raw[:len(raw) // 2], ["truncated.osm.pbf", "cannot read OSM data"]),
            ("PBF blob header claiming 2 GiB", b"\x7f\xff\xff\xff" + b"x" * 64, ["huge.osm.pbf", "max_blob_header_size"]),
            ("empty .osm.pbf", b"", ["empty.osm.pbf", "empty file"]),
        ]:
            name = what.split()[0] + ".osm.pbf"
            name = {"corrupt": "corrupt", "truncated": "truncated", "PBF": "huge", "empty": "empty"}[what.split()[0]]
            path = bad_pbf(name + ".osm.pbf", data)
            case(what, f"preprocess {name}.osm.pbf -o valley.gpkg --overwrite",
                 run("preprocess", path, "-o", cache, "--overwrite", "--no-progress"), 1, fragments, cache, before_cache,
                 "the previous cache, unchanged")

        case("a region too wide for one CRS", "preprocess valley.osm.pbf --bbox 0,40,30,55 -o valley.gpkg --overwrite",
             run("preprocess", ARGS.sample, "--bbox", "0,40,30,55", "-o", cache, "--overwrite", "--no-progress"), 2,
             ["0,40,30,55", "beyond the 0.1 %", "at least 5 regions"], cache, before_cache, "the previous cache, unchanged")
        case("a corridor beyond the road-distance clamp", "preprocess valley.osm.pbf --corridor 150 -o valley.gpkg --overwrite",
             run("preprocess", ARGS.sample, "--corridor", "150", "-o", cache, "--overwrite", "--no-progress"), 2,
             ["corridor_m = 150", "max_distance_m = 100"], cache, before_cache, "the previous cache, unchanged")

        # A route with volumes, localized once: the previous good output.
        route = os.path.join(w, "route")
        os.makedirs(route)
        vol = np.log(np.full((64, 64, 16), 1.0 / (64 * 64 * 16), dtype=np.float32))
        np.save(os.path.join(route, "v0.npy"), vol)
        np.save(os.path.join(route, "v1.npy"), vol)
        json.dump({"format": "seqloc-route", "version": 1}, open(os.path.join(route, "route.json"), "w"))
        good_csv = ("frame,timestamp,volume,crop_x,crop_y,odo_forward_m,odo_left_m,odo_yaw_deg\n"
                    "f0,0,v0.npy,0,0,0,0,0\nf1,1,v1.npy,5,0,5,0,0\n")
        open(os.path.join(route, "frames.csv"), "w").write(good_csv)
        out = os.path.join(w, "out")
        first = run("localize", cache, route, "-o", out, "--window", "64", "--headings", "16", "--no-progress")
        assert first.returncode == 0, first.stderr
        before_out = digest(out)

        def localize_case(what, fragments, setup, undo):
            setup()
            case(what, "localize valley.gpkg route -o out --overwrite",
                 run("localize", cache, route, "-o", out, "--overwrite", "--window", "64", "--headings", "16",
                     "--no-progress"), 1, fragments, out, before_out)
            undo()

        def write_csv(text):
            return lambda: open(os.path.join(route, "frames.csv"), "w").write(text)

        restore_csv = write_csv(good_csv)
        localize_case("frames.csv: a field that is not a number", ["frames.csv:3:", "'fast' is not a finite number"],
                      write_csv(good_csv.replace("f1,1,v1.npy,5,0,5", "f1,1,v1.npy,5,0,fast")), restore_csv)
        localize_case("frames.csv: a row with too few fields", ["frames.csv:3:", "fields"],
                      write_csv(good_csv.replace("f1,1,v1.npy,5,0,5,0,0", "f1,1,v1.npy")), restore_csv)
        localize_case("frames.csv: time going backwards", ["frames.csv:3:", "does not come after"],
                      write_csv(good_csv.replace("f1,1,", "f1,-1,")), restore_csv)
        localize_case("route.json: a member of the wrong type", ["route.json", "\"format\" must be a string"],
                      lambda: open(os.path.join(route, "route.json"), "w").write('{"format": 1, "version": 1}'),
                      lambda: json.dump({"format": "seqloc-route", "version": 1}, open(os.path.join(route, "route.json"), "w")))
        restore_json = lambda: json.dump({"format": "seqloc-route", "version": 1},
                                         open(os.path.join(route, "route.json"), "w"))
        localize_case("route.json: an unknown key", ["route.json", 'unknown key "volume_knd"'],
                      lambda: open(os.path.join(route, "route.json"), "w").write(
                          '{"format": "seqloc-route", "version": 1, "volume_knd": "prob"}'), restore_json)
        # The region's centre, for crops in lat/lon.
        info = json.loads(run("cache", "info", cache, "--json").stdout)
        lat, lon = float(info["centre_lat"]), float(info["centre_lon"])
        geo_csv = ("frame,timestamp,volume,crop_lat,crop_lon,odo_forward_m,odo_left_m,odo_yaw_deg\n"
                   f"f0,0,v0.npy,{lat},{lon},0,0,0\nf1,1,v1.npy,{lon},{lat},5,0,0\n")
        localize_case("frames.csv: crop_lat and crop_lon swapped", ["frames.csv:3:", "outside the region", "swapped"],
                      write_csv(geo_csv), restore_csv)
        localize_case("frames.csv: a crop 100 m from the previous one", ["frames.csv:3:", "previous frame's (line 2)"],
                      write_csv(good_csv.replace("f1,1,v1.npy,5,0", "f1,1,v1.npy,100,0")), restore_csv)
        v1 = os.path.join(route, "v1.npy")
        restore_v1 = lambda: np.save(v1, vol)
        localize_case(".npy in (N, H, W) order, layout not declared",
                      ["v1.npy (frames.csv line 3)", "looks like (N, H, W)", '"layout": "NHW"'],
                      lambda: np.save(v1, np.ascontiguousarray(np.moveaxis(vol, -1, 0))), restore_v1)
        localize_case(".npy that is not 3-D", ["v1.npy"], lambda: np.save(v1, vol[:, :, 0]), restore_v1)
        localize_case(".npy with NaNs", ["v1.npy", "line 3", "NaN"],
                      lambda: np.save(v1, np.where(np.arange(vol.size).reshape(vol.shape) == 7, np.nan, vol).astype(np.float32)),
                      restore_v1)
        localize_case(".npy header claiming 2^60 cells", ["v1.npy"],
                      lambda: npy(v1, vol, "(1048576, 1048576, 1048576)"), restore_v1)
        localize_case(".npy of float64", ["v1.npy", "<f8"], lambda: np.save(v1, vol.astype(np.float64)), restore_v1)
        calibration = os.path.join(w, "calibration.json")
        with open(calibration, "w") as f:
            f.write('{"format": "seqloc-calibration", "version": 2}')
        case("calibration.json of another version", "localize valley.gpkg route -o out --calibration calibration.json "
             "--overwrite", run("localize", cache, route, "-o", out, "--overwrite", "--window", "64", "--headings", "16",
                                "--no-progress", "--calibration", calibration),
             1, ["calibration.json", "version 2"], out, before_out)
        second = os.path.join(w, "valley-east.gpkg")
        shutil.copy(cache, second)
        case("crops in region-grid coordinates with several regions",
             "localize valley.gpkg route -o out --region valley-east.gpkg --overwrite",
             run("localize", cache, route, "-o", out, "--region", second, "--overwrite", "--window", "64", "--headings",
                 "16", "--no-progress"),
             1, ["frames.csv:2:", "region-grid coordinates", "crop_lat, crop_lon"], out, before_out)

        # A cache from another version of the format.
        old = os.path.join(w, "old.gpkg")
        shutil.copy(cache, old)
        db = sqlite3.connect(old)
        db.execute("UPDATE seqloc_metadata SET value = '1' WHERE key = 'format_version'")
        db.commit()
        db.close()
        case("cache of an older format version", "cache info old.gpkg", run("cache", "info", old), 1,
             ["old.gpkg", "format version 1,", "rebuild the cache"])
        notgpkg = bad_pbf("notacache.gpkg", b"SQLite format 3\x00" + os.urandom(2000))
        case("a file that is not a cache", "cache info notacache.gpkg", run("cache", "info", notgpkg), 1, ["notacache.gpkg"])
        case("export of a bbox outside the region", "export valley.gpkg --bbox 0,0,0.01,0.01 -o x.tif",
             run("export", cache, "--bbox", "0,0,0.01,0.01", "-o", os.path.join(w, "x.tif")), 1, ["does not meet the region"])

        # seqloc update: the cache is replaced in one rename at the end, so a refusal leaves it as it was.
        def text_file(name, text):
            path = os.path.join(w, name)
            with open(path, "w") as f:
                f.write(text)
            return path

        nothing = text_file("day.osc", '<?xml version="1.0"?>\n<osmChange version="0.6"></osmChange>\n')
        lacks = text_file("lacks.osc", '<?xml version="1.0"?>\n<osmChange version="0.6"><modify><node '
                                       'id="999999999999" version="5" lat="47.95" lon="11.25"/></modify></osmChange>\n')
        cut = text_file("cut.osc", '<?xml version="1.0"?>\n<osmChange version="0.6"><modify><node id="1" ver')
        other = bad_pbf("other.osm.pbf", raw + b"\0")
        state = text_file("state.txt", "<html>404 Not Found</html>\n")
        for what, args, fragments in [
            ("update: a base the cache was not built from", ["--base", other, "--changes", nothing],
             ["other.osm.pbf", "SHA-256"]),
            ("update: a change file that does not apply to the base", ["--base", ARGS.sample, "--changes", lacks],
             ["lacks.osc", "node 999999999999 v5", "which the base lacks"]),
            ("update: a truncated change file", ["--base", ARGS.sample, "--changes", cut],
             ["cut.osc", "not a complete OSM change file"]),
            ("update: a state file that is not one", ["--base", ARGS.sample, "--changes", nothing, "--state", state],
             ["state.txt:1:", "expected key=value"]),
        ]:
            shown = " ".join(os.path.basename(a) if os.sep in a else a for a in args)
            case(what, f"update valley.gpkg {shown}".replace(os.path.basename(ARGS.sample), "valley.osm.pbf"),
                 run("update", cache, *args, "--no-progress"), 1, fragments, cache, before_cache,
                 "the previous cache, unchanged")

        # The server: bad requests are answered, never crash it.
        server = subprocess.Popen([ARGS.seqloc, "serve", cache, "--port", "0"], stdout=subprocess.PIPE,
                                  stderr=subprocess.PIPE, text=True)
        try:
            base = server.stdout.readline().split()[2].rstrip("/")
            http_case("tile outside the region", base, "/regions/valley/classes/999/0.png", 404, "outside")
            http_case("crop of 100 km", base, "/regions/valley/crop?lat=47.95&lon=11.25&size_m=100000", 400, "above the limit")
            http_case("malformed %-escape in the query", base, "/regions/valley/crop?lat=%zz", 400, "malformed")
            http_case("parameter bytes that are not UTF-8", base, "/regions/valley/crop?lat=4%FE&lon=1", 400, "not a number")
            http_case("unknown region", base, "/regions/atlantis/classes/0/0.png", 404, "no region")
        finally:
            server.terminate()
            server.wait(timeout=30)
    finally:
        shutil.rmtree(w, ignore_errors=True)

    if ARGS.markdown:
        print("| bad input | command | what the user sees (last line of stderr, or the JSON error) | exit | what is kept |")
        print("|---|---|---|---|---|")
        for what, command, message, code, kept in ROWS:
            message = message.replace(w, "").replace("|", "\\|")
            print(f"| {what} | `{command}` | {message} | {code} | {kept} |")
    for f in FAILURES:
        print("FAILED: " + f, file=sys.stderr)
    print(f"{len(ROWS)} bad inputs tried, {len(FAILURES)} failures", file=sys.stderr)
    sys.exit(1 if FAILURES else 0)


if __name__ == "__main__":
    main()
