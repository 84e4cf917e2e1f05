"""`seqloc localize --mcap` read back by others' readers (docs/ros.md): every ROS 2 bag is read by
@mcap/core and decoded by @foxglove/rosmsg2-serialization (read_bag.mjs), and every message is
compared with what the run's poses.csv and the route's frames.csv say, through conversions done
here independently of seqloc: the local east-north-up frame from WGS84 by hand (ECEF), the
meridian convergence from PROJ (GDAL's osr) on the cache's own CRS. metadata.yaml is read by a YAML
parser and checked against the MCAP file.

The fixture: the sample region, two simulated routes; route_000's frame ids hold commas and quotes
and some of its frames have no true heading, route_001 has no ground truth at all."""

import argparse
import csv
import json
import math
import os
import subprocess
import sys
import tempfile
import unittest

import numpy as np
import yaml
from osgeo import gdal, osr

gdal.UseExceptions()
ARGS = None
A, F = 6378137.0, 1 / 298.257223563  # WGS84
E2 = F * (2 - F)
UNMEASURED = 1e6


def run(*cmd, expect=0):
    r = subprocess.run([str(c) for c in cmd], capture_output=True, text=True, timeout=600)
    if r.returncode != expect:
        raise AssertionError(f"{cmd[:3]}: exit {r.returncode}, expected {expect}\n{r.stdout}\n{r.stderr}")
    return r


def ecef(lat, lon):
    p, l = math.radians(lat), math.radians(lon)
    n = A / math.sqrt(1 - E2 * math.sin(p) ** 2)
    return np.array([n * math.cos(p) * math.cos(l), n * math.cos(p) * math.sin(l), n * (1 - E2) * math.sin(p)])


def enu_axes(lat, lon):
    """East, north, up unit vectors at a point, in ECEF."""
    p, l = math.radians(lat), math.radians(lon)
    return np.array([[-math.sin(l), math.cos(l), 0],
                     [-math.sin(p) * math.cos(l), -math.sin(p) * math.sin(l), math.cos(p)],
                     [math.cos(p) * math.cos(l), math.cos(p) * math.sin(l), math.sin(p)]])


class LocalFrame:
    def __init__(self, lat0, lon0):
        self.origin, self.axes = ecef(lat0, lon0), enu_axes(lat0, lon0)

    def position(self, lat, lon):
        return self.axes @ (ecef(lat, lon) - self.origin)

    def turn(self, lat, lon):
        """The point's own east-north axes in the frame's x-y (2 x 2)."""
        return (self.axes @ enu_axes(lat, lon).T)[:2, :2]

    def yaw_deg(self, lat, lon, compass_deg):
        b = math.radians(compass_deg)
        v = self.turn(lat, lon) @ np.array([math.sin(b), math.cos(b)])
        return math.degrees(math.atan2(v[1], v[0]))


def angle_diff(a, b):
    return abs((a - b + 180) % 360 - 180)


def yaw_of(q):
    assert abs(q["x"]) < 1e-12 and abs(q["y"]) < 1e-12, q
    assert abs(q["z"] ** 2 + q["w"] ** 2 - 1) < 1e-12, q
    return math.degrees(2 * math.atan2(q["z"], q["w"]))


def read_csv(path):
    with open(path, newline="") as f:
        return list(csv.DictReader(f))


def read_bag(mcap):
    r = subprocess.run(["node", os.path.join(os.path.dirname(__file__), "read_bag.mjs"), mcap],
                       capture_output=True, text=True, timeout=300)
    if r.returncode != 0:
        raise AssertionError(f"read_bag.mjs {mcap}: exit {r.returncode}\n{r.stderr}")
    return json.loads(r.stdout)


class Convergence:
    """gamma at a point (compass = grid + gamma) from PROJ on the cache's CRS."""

    def __init__(self, cache):
        srs = osr.SpatialReference()
        srs.ImportFromWkt(gdal.Open(f"GPKG:{cache}:classes").GetProjection())
        wgs = osr.SpatialReference()
        wgs.ImportFromEPSG(4326)
        wgs.SetAxisMappingStrategy(osr.OAMS_TRADITIONAL_GIS_ORDER)
        self.to_grid = osr.CoordinateTransformation(wgs, srs)

    def __call__(self, lat, lon):
        x0, y0, _ = self.to_grid.TransformPoint(lon, lat)
        x1, y1, _ = self.to_grid.TransformPoint(lon, lat + 1e-5)
        return -math.degrees(math.atan2(x1 - x0, y1 - y0))  # true north's grid heading is -gamma


def rotate(r, s):
    return r @ s @ r.T


class Bags(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.tmp = tempfile.TemporaryDirectory()
        d = cls.tmp.name
        cls.cache = os.path.join(d, "valley.gpkg")
        run(ARGS.seqloc, "preprocess", ARGS.sample, "-o", cls.cache, "--no-progress")
        routes = os.path.join(d, "routes")
        run(ARGS.seqloc, "simulate", cls.cache, "-o", routes, "--routes", "2", "--frames", "10", "--seed", "11")
        cls.routes = [os.path.join(routes, "route_000"), os.path.join(routes, "route_001")]
        cls.edit_frames(cls.routes[0], lambda i, row: row.update(
            frame=f'img,{i:03d} "left"', gt_heading_deg="" if i in (3, 4) else row["gt_heading_deg"]))
        cls.edit_frames(cls.routes[1], lambda i, row: [row.pop(k) for k in ("gt_lat", "gt_lon", "gt_heading_deg")])
        cls.out = os.path.join(d, "out")
        run(ARGS.seqloc, "localize", cls.cache, *cls.routes, "-o", cls.out, "--mode", "all", "--mcap",
            "--window", "160", "--no-progress")
        cls.convergence = Convergence(cls.cache)

    @classmethod
    def tearDownClass(cls):
        cls.tmp.cleanup()

    @staticmethod
    def edit_frames(route, edit):
        path = os.path.join(route, "frames.csv")
        rows = read_csv(path)
        for i, row in enumerate(rows):
            edit(i, row)
        with open(path, "w", newline="") as f:
            w = csv.DictWriter(f, fieldnames=list(rows[0].keys()))
            w.writeheader()
            w.writerows(rows)

    def bag(self, route, mode):
        folder = os.path.join(self.out, route, mode, "bag")
        with open(os.path.join(folder, "metadata.yaml")) as f:
            meta = yaml.safe_load(f)["rosbag2_bagfile_information"]
        return folder, meta, read_bag(os.path.join(folder, "bag_0.mcap"))

    def test_only_the_modes_with_a_belief_have_bags(self):
        for route in ("route_000", "route_001"):
            for mode in ("online", "seqloc", "smooth"):
                self.assertTrue(os.path.isfile(os.path.join(self.out, route, mode, "bag", "bag_0.mcap")), (route, mode))
            for mode in ("single", "offline"):
                self.assertFalse(os.path.exists(os.path.join(self.out, route, mode, "bag")), (route, mode))

    def test_metadata_yaml_matches_the_mcap_file(self):
        for route in ("route_000", "route_001"):
            folder, meta, bag = self.bag(route, "seqloc")
            self.assertEqual(meta["storage_identifier"], "mcap")
            self.assertEqual(meta["relative_file_paths"], ["bag_0.mcap"])
            self.assertTrue(os.path.isfile(os.path.join(folder, meta["relative_file_paths"][0])))
            by_topic = {c["topic"]: bag["statistics"]["channel_message_counts"][str(c["id"])] for c in bag["channels"]}
            yaml_topics = {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]}
            self.assertEqual(yaml_topics, {k: int(v) for k, v in by_topic.items()})
            types = {c["topic"]: next(s["name"] for s in bag["schemas"] if s["id"] == c["schema_id"])
                     for c in bag["channels"]}
            self.assertEqual({t["topic_metadata"]["name"]: t["topic_metadata"]["type"]
                              for t in meta["topics_with_message_count"]}, types)
            self.assertEqual(meta["message_count"], len(bag["messages"]))
            self.assertEqual(int(bag["statistics"]["message_count"]), len(bag["messages"]))
            times = [int(m["log_time"]) for m in bag["messages"]]
            self.assertEqual(meta["starting_time"]["nanoseconds_since_epoch"], min(times))
            self.assertEqual(meta["duration"]["nanoseconds"], max(times) - min(times))
            self.assertEqual(meta["files"][0]["message_count"], len(bag["messages"]))
            seqloc_meta = bag["metadata"][0]["metadata"]
            for key in ("frame_id", "origin_lat_deg", "origin_lon_deg", "route", "mode"):
                self.assertEqual(str(meta["custom_data"][key]), seqloc_meta[key], key)

    def test_the_file_is_a_ros2_mcap_with_every_record_kind(self):
        _, _, bag = self.bag("route_000", "smooth")
        self.assertEqual(bag["header"]["profile"], "ros2")
        self.assertNotEqual(bag["data_section_crc"], 0)
        for kind in ("Schema", "Channel", "Metadata", "Message", "MessageIndex", "DataEnd", "Statistics",
                     "ChunkIndex", "MetadataIndex", "SummaryOffset", "Footer"):
            self.assertIn(kind, bag["record_types"])
        self.assertEqual(bag["chunk_indexes"], bag["statistics"]["chunk_count"])
        self.assertEqual(len({s["name"] for s in bag["schemas"]}), len(bag["schemas"]))  # each type once
        self.assertTrue(all(s["encoding"] == "ros2msg" for s in bag["schemas"]))
        self.assertTrue(all(c["message_encoding"] == "cdr" for c in bag["channels"]))

    def test_every_message_matches_poses_csv_and_frames_csv(self):
        for route in ("route_000", "route_001"):
            for mode in ("online", "seqloc", "smooth"):
                with self.subTest(route=route, mode=mode):
                    self.check_route(route, mode)

    def check_route(self, route, mode):
        _, _, bag = self.bag(route, mode)
        poses = read_csv(os.path.join(self.out, route, mode, "poses.csv"))
        frames = read_csv(os.path.join(self.routes[0 if route == "route_000" else 1], "frames.csv"))
        meta = bag["metadata"][0]["metadata"]
        with_truth = "gt_lat" in frames[0]
        # The origin: the first true position, else the first pose (to 1e-9 degrees).
        first = (frames[0]["gt_lat"], frames[0]["gt_lon"]) if with_truth else (poses[0]["lat"], poses[0]["lon"])
        self.assertAlmostEqual(float(meta["origin_lat_deg"]), float(first[0]), delta=1e-9)
        self.assertAlmostEqual(float(meta["origin_lon_deg"]), float(first[1]), delta=1e-9)
        frame = LocalFrame(float(meta["origin_lat_deg"]), float(meta["origin_lon_deg"]))
        by_topic = {}
        for m in bag["messages"]:
            self.assertEqual(m["log_time"], m["publish_time"])
            by_topic.setdefault(m["topic"], []).append(m)
        expected_topics = {"/seqloc/pose", "/seqloc/fix", "/seqloc/diagnostics", "/seqloc/frame"}
        if with_truth:
            expected_topics |= {"/seqloc/truth/pose", "/seqloc/truth/fix"}
        self.assertEqual(set(by_topic), expected_topics)
        for topic in ("/seqloc/pose", "/seqloc/fix", "/seqloc/diagnostics", "/seqloc/frame"):
            self.assertEqual(len(by_topic[topic]), len(poses), topic)
            self.assertEqual([m["sequence"] for m in by_topic[topic]], list(range(len(poses))), topic)
        for i, (p, f) in enumerate(zip(poses, frames)):
            t_ns = round(float(f["timestamp"]) * 1e9)
            for topic in ("/seqloc/pose", "/seqloc/fix", "/seqloc/diagnostics", "/seqloc/frame"):
                m = by_topic[topic][i]
                self.assertEqual(int(m["log_time"]), t_ns, (topic, i))
            self.assertEqual(by_topic["/seqloc/frame"][i]["message"]["data"], p["frame"])
            self.assertEqual(p["frame"], f["frame"])
            self.check_estimate(frame, p, by_topic["/seqloc/pose"][i]["message"], by_topic["/seqloc/fix"][i]["message"],
                                t_ns)
            self.check_diagnostics(route, mode, p, by_topic["/seqloc/diagnostics"][i]["message"])
        if with_truth:
            self.check_truth(frame, frames, by_topic)

    def check_estimate(self, frame, p, pose, fix, t_ns):
        lat, lon = float(p["lat"]), float(p["lon"])
        self.assertEqual(pose["header"]["stamp"]["sec"] * 10**9 + pose["header"]["stamp"]["nanosec"], t_ns)
        self.assertEqual(pose["header"]["frame_id"], "seqloc_enu")
        self.assertEqual(fix["header"]["frame_id"], "base_link")
        # The fix: WGS84 as poses.csv has it (9 decimals), its covariance the grid's turned by gamma.
        self.assertAlmostEqual(fix["latitude"], lat, delta=6e-10)
        self.assertAlmostEqual(fix["longitude"], lon, delta=6e-10)
        self.assertEqual(fix["altitude"], "NaN")
        self.assertEqual(fix["position_covariance_type"], 1)
        grid = np.array([[float(p["cov_xx_m2"]), float(p["cov_xy_m2"])], [float(p["cov_xy_m2"]), float(p["cov_yy_m2"])]])
        g = math.radians(self.convergence(lat, lon))
        at_fix = rotate(np.array([[math.cos(g), math.sin(g)], [-math.sin(g), math.cos(g)]]), grid)
        c = np.array(fix["position_covariance"]).reshape(3, 3)
        tol = 2e-5 * np.trace(grid)  # poses.csv keeps 6 significant digits
        np.testing.assert_allclose(c[:2, :2], at_fix, atol=tol)
        np.testing.assert_array_equal(c[2, :2], [0, 0])
        np.testing.assert_array_equal(c[:2, 2], [0, 0])
        self.assertEqual(c[2, 2], UNMEASURED)
        # The pose: the local frame's position, yaw and covariance.
        xyz = pose["pose"]["pose"]["position"]
        np.testing.assert_allclose([xyz["x"], xyz["y"], xyz["z"]], frame.position(lat, lon), atol=1e-3)
        self.assertLess(angle_diff(yaw_of(pose["pose"]["pose"]["orientation"]),
                                   frame.yaw_deg(lat, lon, float(p["heading_deg"]))), 2e-4)
        cov = np.array(pose["pose"]["covariance"]).reshape(6, 6)
        np.testing.assert_allclose(cov[:2, :2], rotate(frame.turn(lat, lon), at_fix), atol=tol)
        self.assertEqual([cov[k, k] for k in (2, 3, 4)], [UNMEASURED] * 3)
        sd = math.radians(float(p["heading_sd_deg"]))
        self.assertAlmostEqual(cov[5, 5], sd * sd, delta=2 * sd * math.radians(6e-5))
        off = cov.copy()
        for k in range(6):
            off[k, k] = 0
        off[0, 1] = off[1, 0] = 0
        np.testing.assert_array_equal(off, np.zeros((6, 6)))

    def check_diagnostics(self, route, mode, p, msg):
        self.assertEqual(len(msg["status"]), 1)
        s = msg["status"][0]
        values = {kv["key"]: kv["value"] for kv in s["values"]}
        self.assertEqual(s["hardware_id"], route)
        self.assertEqual(s["name"], f"seqloc/{mode}")
        self.assertEqual(values["frame"], p["frame"])
        multimodal = p["multimodal"] == "1"
        self.assertEqual(values["multimodal"], "true" if multimodal else "false")
        self.assertEqual(s["level"], 1 if multimodal else 0)
        self.assertEqual(values["relocalized"], "true" if p["relocalized"] == "1" else "false")
        self.assertAlmostEqual(float(values["mass_within_5m"]), float(p["mass_5m"]), delta=1e-4)
        self.assertAlmostEqual(float(values["second_mode_share"]), float(p["second_mode_share"]), delta=1e-4)
        self.assertEqual(values["region"], p["region"])

    def check_truth(self, frame, frames, by_topic):
        fixes, truth_poses = by_topic["/seqloc/truth/fix"], by_topic["/seqloc/truth/pose"]
        self.assertEqual(len(fixes), len(frames))
        with_heading = [f for f in frames if f["gt_heading_deg"] != ""]
        self.assertEqual(len(truth_poses), len(with_heading))
        self.assertLess(len(with_heading), len(frames))  # the fixture left some headings out
        for m, f in zip(fixes, frames):
            self.assertEqual(int(m["log_time"]), round(float(f["timestamp"]) * 1e9))
            self.assertEqual(m["message"]["latitude"], float(f["gt_lat"]))
            self.assertEqual(m["message"]["longitude"], float(f["gt_lon"]))
            self.assertEqual(m["message"]["position_covariance_type"], 0)
        for m, f in zip(truth_poses, with_heading):
            self.assertEqual(int(m["log_time"]), round(float(f["timestamp"]) * 1e9))
            lat, lon = float(f["gt_lat"]), float(f["gt_lon"])
            xyz = m["message"]["pose"]["position"]
            np.testing.assert_allclose([xyz["x"], xyz["y"], xyz["z"]], frame.position(lat, lon), atol=1e-3)
            self.assertLess(angle_diff(yaw_of(m["message"]["pose"]["orientation"]),
                                       frame.yaw_deg(lat, lon, float(f["gt_heading_deg"]))), 1e-6)

    def test_frame_names_and_origin_given_on_the_command_line(self):
        out = os.path.join(self.tmp.name, "named")
        run(ARGS.seqloc, "localize", self.cache, self.routes[1], "-o", out, "--mcap", "--mcap-frame-id", "map",
            "--mcap-base-frame", "gnss_link", "--mcap-origin", "47.95,11.24", "--window", "160", "--no-progress")
        bag = read_bag(os.path.join(out, "route_001", "seqloc", "bag", "bag_0.mcap"))
        meta = bag["metadata"][0]["metadata"]
        self.assertEqual((meta["origin_lat_deg"], meta["origin_lon_deg"]), ("47.950000000", "11.240000000"))
        for m in bag["messages"]:
            want = {"/seqloc/pose": "map", "/seqloc/fix": "gnss_link"}.get(m["topic"])
            if want:
                self.assertEqual(m["message"]["header"]["frame_id"], want)
        # The first pose against a frame built here on that origin.
        first = read_csv(os.path.join(out, "route_001", "seqloc", "poses.csv"))[0]
        xyz = next(m for m in bag["messages"] if m["topic"] == "/seqloc/pose")["message"]["pose"]["pose"]["position"]
        np.testing.assert_allclose([xyz["x"], xyz["y"]],
                                   LocalFrame(47.95, 11.24).position(float(first["lat"]), float(first["lon"]))[:2],
                                   atol=1e-3)

    def test_refusals_write_nothing(self):
        for extra, says in ((["--mode", "single", "--mcap"], "carry no uncertainty"),
                            (["--mode", "offline", "--mcap"], "carry no uncertainty"),
                            (["--mcap", "--mcap-origin", "95,11"], "is not a latitude"),
                            (["--mcap", "--mcap-origin", "47"], "expected LAT,LON"),
                            (["--mcap", "--mcap-frame-id", ""], "must not be empty"),
                            (["--mcap-frame-id", "map"], "go with --mcap")):
            out = os.path.join(self.tmp.name, "refused")
            r = run(ARGS.seqloc, "localize", self.cache, self.routes[0], "-o", out, *extra, "--no-progress", expect=2)
            self.assertIn(says, r.stderr, extra)
            self.assertEqual(len(r.stderr.strip().splitlines()), 1, r.stderr)
            self.assertFalse(os.path.exists(out), extra)


if __name__ == "__main__":
    parser = argparse.ArgumentParser()
    parser.add_argument("--seqloc", required=True)
    parser.add_argument("--sample", required=True)
    ARGS, rest = parser.parse_known_args()
    unittest.main(argv=[sys.argv[0]] + rest)
