"""The viewer page in headless Chromium: `seqloc serve` with the built page, a track from
`seqloc localize` on the sample region; the page must load the region's tiles without errors and
draw every frame of the track, and the screenshot must show the map, the ground truth and the
frames coloured by position error. Three times: in the region's own projection, over a Web
Mercator view from the server's XYZ tiles (?web=1), and with no seqloc server at all: the page as
static files beside a PMTiles archive of the region (?pmtiles=), read by HTTP range requests from a
plain static file server (one written here, as a CDN or object store answers them)."""

import argparse
import http.server
import os
import re
import shutil
import subprocess
import sys
import tempfile
import threading

from osgeo import gdal


def run(*cmd):
    r = subprocess.run(cmd, capture_output=True, text=True, timeout=600)
    if r.returncode != 0:
        sys.exit(f"{' '.join(cmd)} failed ({r.returncode}): {r.stderr}")
    return r.stdout


def main():
    p = argparse.ArgumentParser()
    p.add_argument("--seqloc", required=True)
    p.add_argument("--sample", required=True, help="the sample region's .osm.pbf")
    p.add_argument("--web", required=True, help="the built viewer page")
    p.add_argument("--chromium", default="chromium")
    a = p.parse_args()
    if not os.path.isfile(os.path.join(a.web, "app.js")):
        sys.exit(f"{a.web}: the viewer page was not built (run scripts/deps build, then build again)")
    with tempfile.TemporaryDirectory() as d:
        cache = os.path.join(d, "sample.gpkg")
        run(a.seqloc, "preprocess", a.sample, "-o", cache, "--no-progress")
        run(a.seqloc, "simulate", cache, "-o", os.path.join(d, "routes"), "--routes", "1", "--frames", "12", "--seed", "5")
        run(a.seqloc, "localize", cache, os.path.join(d, "routes", "route_000"), "-o", os.path.join(d, "out"),
            "--window", "128")
        web = os.path.join(d, "web")
        shutil.copytree(a.web, web)
        shutil.copy(os.path.join(d, "out", "route_000", "seqloc", "track.geojson"), web)
        server = subprocess.Popen([a.seqloc, "serve", cache, "--port", "0", "--web", web],
                                  stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        failures = []
        try:
            base = server.stdout.readline().split()[2]
            for label, query in (("region projection", "?track=static/track.geojson&distance=1"),
                                 ("web mercator", "?web=1&track=static/track.geojson&distance=1")):
                failures += [f"{label}: {f}" for f in check_page(a.chromium, base + query, d, label)]
        finally:
            server.terminate()
            server.wait(timeout=20)
        # No seqloc server: the built page as static files (index.html, the bundle under static/),
        # the archive and the track beside it.
        site = os.path.join(d, "site")
        os.makedirs(os.path.join(site, "static"))
        for name in os.listdir(a.web):
            target = site if name == "index.html" else os.path.join(site, "static")
            shutil.copy(os.path.join(a.web, name), target)
        run(a.seqloc, "export", cache, "-o", os.path.join(site, "sample.pmtiles"), "--no-progress")
        shutil.copy(os.path.join(d, "out", "route_000", "seqloc", "track.geojson"), site)
        static = http.server.ThreadingHTTPServer(("127.0.0.1", 0), lambda *args: RangeHandler(*args, directory=site))
        threading.Thread(target=static.serve_forever, daemon=True).start()
        try:
            url = f"http://127.0.0.1:{static.server_address[1]}/index.html?pmtiles=sample.pmtiles&track=track.geojson"
            failures += [f"static pmtiles: {f}" for f in check_page(a.chromium, url, d, "static pmtiles")]
        finally:
            static.shutdown()
        if failures:
            sys.exit("; ".join(failures))
        print("3 passed, 0 failed")


class RangeHandler(http.server.SimpleHTTPRequestHandler):
    """Static files with single byte ranges (Range: bytes=A-B), as object stores and CDNs serve them."""

    def send_head(self):
        self.range_left = None
        wanted = re.fullmatch(r"bytes=(\d+)-(\d*)", self.headers.get("Range", ""))
        path = self.translate_path(self.path)
        if not wanted or not os.path.isfile(path):
            return super().send_head()
        size = os.path.getsize(path)
        start = int(wanted.group(1))
        end = min(size - 1, int(wanted.group(2)) if wanted.group(2) else size - 1)
        if start >= size:
            self.send_error(416)
            return None
        f = open(path, "rb")
        f.seek(start)
        self.send_response(206)
        self.send_header("Content-Type", self.guess_type(path))
        self.send_header("Content-Range", f"bytes {start}-{end}/{size}")
        self.send_header("Content-Length", str(end - start + 1))
        self.send_header("Accept-Ranges", "bytes")
        self.end_headers()
        self.range_left = end - start + 1
        return f

    def copyfile(self, source, outputfile):
        left = self.range_left
        if left is None:
            return super().copyfile(source, outputfile)
        while left > 0:
            chunk = source.read(min(65536, left))
            if not chunk:
                break
            outputfile.write(chunk)
            left -= len(chunk)

    def log_message(self, *args):
        pass


def check_page(chromium_binary, url, d, label):
    chromium = [chromium_binary, "--headless=new", "--no-sandbox", "--disable-gpu", "--hide-scrollbars",
                "--window-size=1200,800", "--virtual-time-budget=15000"]
    dom = subprocess.run(chromium + ["--dump-dom", url], capture_output=True, text=True, timeout=120).stdout
    shot = os.path.join(d, "viewer.png")
    subprocess.run(chromium + [f"--screenshot={shot}", url], capture_output=True, timeout=120)
    m = re.search(r'<div id="status"[^>]*data-tiles="(\d+)" data-tile-errors="(\d+)" data-track-points="(\d+)"', dom)
    if not m:
        return ["the page reported no status; its DOM:\n" + dom[:3000]]
    tiles, errors, points = map(int, m.groups())
    failures = []
    if tiles < 4:
        failures.append(f"only {tiles} tiles loaded")
    if errors:
        failures.append(f"{errors} tiles failed to load")
    if points != 12:
        failures.append(f"{points} track points drawn, expected 12")
    if "ol-scale-line" not in dom:
        failures.append("no scale bar")
    # The screenshot: the map part (left of the 320 px panel) is not blank, and track points
    # (viridis colours: green-blue-yellow with little red) are drawn on it.
    ds = gdal.Open(shot)
    r, g, b = (ds.GetRasterBand(i + 1).ReadAsArray()[:, : ds.RasterXSize - 330].astype(int) for i in range(3))
    distinct = len(set(zip(r[::7, ::7].ravel(), g[::7, ::7].ravel(), b[::7, ::7].ravel())))
    if distinct < 20:
        failures.append(f"the map looks blank ({distinct} colours)")
    outline = ((r < 30) & (g < 30) & (b < 30)).sum()
    if outline < 50:
        failures.append("no track outline (black) pixels on the map")
    # The ground truth (the simulated route has it): a dashed blue line, rgb(30, 90, 220).
    truth = ((r < 70) & (g > 60) & (g < 130) & (b > 180)).sum()
    if truth < 20:
        failures.append(f"no ground-truth (blue) pixels on the map ({truth})")
    # The frames coloured by position error (the default with ground truth), in render's classes.
    classes = {"< 1 m": (26, 152, 80), "< 3 m": (145, 207, 96), "< 5 m": (253, 174, 97), ">= 5 m": (215, 48, 39)}
    by_error = {name: int(((abs(r - c[0]) <= 6) & (abs(g - c[1]) <= 6) & (abs(b - c[2]) <= 6)).sum())
                for name, c in classes.items()}
    if sum(by_error.values()) < 30:
        failures.append(f"no frames coloured by position error ({by_error})")
    print(f"viewer, {label}: {tiles} tiles, {errors} errors, {points} track points, {distinct} colours, "
          f"{outline} dark px, {truth} ground-truth px, error classes {by_error}")
    return failures


if __name__ == "__main__":
    main()
