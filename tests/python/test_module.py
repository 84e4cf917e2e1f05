"""The seqloc Python module, checked against GDAL reading the same cache and against the filter's
own analytic behaviour. Run by ctest with PYTHONPATH set to the built module and SEQLOC_TEST_CACHE
to a region cache."""

import csv
import math
import os
import shutil
import subprocess
import tempfile
import unittest

import numpy as np
from osgeo import gdal

import seqloc

CACHE = os.environ["SEQLOC_TEST_CACHE"]
SEQLOC = os.environ.get("SEQLOC_BINARY")
gdal.UseExceptions()


def gdal_window(table, geotransform, size):
    """The cache's raster read by GDAL's GeoPackage driver at a crop's geotransform."""
    ds = gdal.Open(f"GPKG:{CACHE}:{table}")
    gt = ds.GetGeoTransform()
    x0 = round((geotransform[0] - gt[0]) / gt[1])
    y0 = round((geotransform[3] - gt[3]) / gt[5])
    # GDAL's GeoPackage driver reads the road distance through the coverage's scale, in metres.
    return [ds.GetRasterBand(b + 1).ReadAsArray(x0, y0, size, size) for b in range(ds.RasterCount)]


class CacheCrop(unittest.TestCase):
    def setUp(self):
        self.cache = seqloc.Cache(CACHE)
        info = self.cache.info
        self.centre = (info.centre_lat, info.centre_lon)

    def test_crop_equals_gdal_reading_the_geopackage(self):
        for size_m, lat_off in ((64.0, 0.0), (50.5, 0.001), (128.0, -0.002)):
            lat, lon = self.centre[0] + lat_off, self.centre[1] + lat_off
            crop = self.cache.crop(lat, lon, size_m)
            n = round(size_m * 2)
            self.assertEqual(crop.classes.shape, (n, n, 3))
            self.assertEqual(crop.classes.dtype, np.uint8)
            self.assertEqual(crop.road_distance.dtype, np.float32)
            classes = gdal_window("classes", crop.geotransform, n)
            for c in range(3):
                np.testing.assert_array_equal(crop.classes[:, :, c], classes[c])
            (metres,) = gdal_window("road_distance", crop.geotransform, n)
            np.testing.assert_allclose(crop.road_distance, metres, atol=1e-4)
            d = crop.road_distance.astype(np.float64)
            np.testing.assert_allclose(crop.road_prior, np.exp(-d * d / (2 * 3.0**2)), atol=1e-6)
            # The crop's centre is within half a cell of the point (a cell centre or corner).
            x, y = self.cache.to_grid(lat, lon)
            self.assertLessEqual(abs(x - crop.crop_x), 0.25 + 1e-9)
            self.assertLessEqual(abs(y - crop.crop_y), 0.25 + 1e-9)

    def test_crop_by_region_metres_is_the_crop_by_lat_lon(self):
        lat, lon = self.centre[0] + 0.0007, self.centre[1] - 0.0004
        x, y = self.cache.to_grid(lat, lon)
        by_geo = self.cache.crop(lat, lon, 40.0)
        by_metres = self.cache.crop(x=x, y=y, size_m=40.0)
        self.assertEqual(by_geo.geotransform, by_metres.geotransform)
        for name in ("classes", "road_distance", "road_prior"):
            np.testing.assert_array_equal(getattr(by_geo, name), getattr(by_metres, name), name)
        # from_grid inverts to_grid (to well under a millimetre).
        back = self.cache.from_grid(x, y)
        self.assertAlmostEqual(back[0], lat, places=9)
        self.assertAlmostEqual(back[1], lon, places=9)
        with self.assertRaises(TypeError):
            self.cache.crop(lat, lon, 40.0, x=x, y=y)  # both: ambiguous
        with self.assertRaises(TypeError):
            self.cache.crop(x=x, size_m=40.0)
        with self.assertRaises(ValueError):
            self.cache.crop(x=x + 1e6, y=y, size_m=40.0)  # outside the region

    def test_arrays_are_not_copies(self):
        crop = self.cache.crop(*self.centre, 32.0)
        for name in ("classes", "road_distance", "road_prior"):
            self.assertFalse(getattr(crop, name).flags["OWNDATA"], name)  # owned by the C++ buffer's capsule
            self.assertTrue(getattr(crop, name).flags["C_CONTIGUOUS"], name)

    def test_bad_requests_raise(self):
        with self.assertRaises(ValueError):
            self.cache.crop(*self.centre, 100000.0)
        with self.assertRaises(ValueError):
            self.cache.crop(0.0, 0.0, 64.0)
        with self.assertRaises(ValueError):
            self.cache.crop(*self.centre, 64.0, layers=["roads"])
        with self.assertRaises(OSError):
            seqloc.Cache("/nonexistent.gpkg")
        # One hierarchy (docs/python.md), by category: each under seqloc.Error and the built-in it was before.
        with self.assertRaises(seqloc.NotFoundError):  # a point outside the region
            self.cache.crop(0.0, 0.0, 64.0)
        with self.assertRaises(seqloc.RequestError):  # the earlier name, a usage error
            self.cache.crop(0.0, 0.0, 64.0)
        with self.assertRaises(seqloc.IOError):
            seqloc.Cache("/nonexistent.gpkg")
        with self.assertRaises(seqloc.CacheError):  # the earlier name, an I/O error
            seqloc.Cache("/nonexistent.gpkg")

    def test_errors_form_one_hierarchy(self):
        for cls, builtin in [(seqloc.UsageError, ValueError), (seqloc.DataError, ValueError),
                             (seqloc.NotFoundError, seqloc.UsageError), (seqloc.NotFoundError, LookupError),
                             (seqloc.IOError, OSError), (seqloc.InternalError, RuntimeError),
                             (seqloc.CacheError, OSError), (seqloc.FilterError, seqloc.DataError),
                             (seqloc.RequestError, seqloc.UsageError), (seqloc.UsageTypeError, TypeError),
                             (seqloc.UsageTypeError, seqloc.UsageError), (seqloc.UsageKeyError, KeyError),
                             (seqloc.UsageKeyError, seqloc.UsageError), (seqloc.UsageIndexError, IndexError),
                             (seqloc.UsageIndexError, seqloc.UsageError)]:
            self.assertTrue(issubclass(cls, seqloc.Error), cls.__name__)
            self.assertTrue(issubclass(cls, builtin), cls.__name__)
            self.assertEqual(cls.__module__, "seqloc", cls.__name__)


class FilterOnline(unittest.TestCase):
    def test_a_peaked_volume_is_found_where_it_peaks(self):
        f = seqloc.Filter({"width": 64, "height": 64, "headings": 32, "mgr": False})
        vol = np.full((31, 31, 32), -20.0, np.float32)
        vol[10, 20, 8] = 0.0  # 8 * 360 / 32 = 90 degrees
        r = f.step(vol, (0.0, 0.0, 0.0), (32.0, 32.0, 0.0))
        # Volume cell (v, u) = (10, 20) lies (20 - 15, 10 - 15) cells from the crop centre.
        self.assertAlmostEqual(r.argmax.u, 37.0)
        self.assertAlmostEqual(r.argmax.v, 27.0)
        self.assertAlmostEqual(r.grid_heading_deg, 90.0)
        self.assertLess(r.frame_entropy, 0.2)

    def test_without_a_crop_pose_the_volume_sits_at_the_window_centre(self):
        f = seqloc.Filter({"width": 64, "height": 48, "headings": 32, "mgr": False})
        vol = np.full((31, 31, 32), -20.0, np.float32)
        vol[15, 15, 0] = 0.0  # the volume's centre cell
        r = f.step(vol)
        # The window's centre: cell ((64 - 1) / 2, (48 - 1) / 2), within the half cell a cell
        # grid allows, not the window's corner.
        self.assertAlmostEqual(r.argmax.u, 31.5, delta=0.5)
        self.assertAlmostEqual(r.argmax.v, 23.5, delta=0.5)

    def test_belief_marginal_is_the_belief_over_the_window(self):
        f = seqloc.Filter({"width": 40, "height": 30, "headings": 16, "mgr": False})
        vol = np.full((21, 21, 16), -25.0, np.float32)
        vol[4, 12, 3] = 0.0
        r = f.step(vol, crop_pose=(20.0, 15.0, 0.0))
        marginal = f.belief_marginal()
        self.assertEqual((marginal.shape, marginal.dtype), ((30, 40), np.float32))
        self.assertAlmostEqual(float(marginal.sum()), 1.0, places=4)
        v, u = np.unravel_index(np.argmax(marginal), marginal.shape)
        self.assertEqual((u, v), (round(r.argmax.u), round(r.argmax.v)))

    def test_arrays_from_dlpack_and_array_interface_give_the_same_step(self):
        vol = np.full((15, 15, 16), -25.0, np.float32)
        vol[3, 9, 4] = 0.0

        class DLPackOnly:  # a tensor from another library: only the DLPack protocol
            def __init__(self, a):
                self.a = a

            def __dlpack__(self, stream=None):
                return self.a.__dlpack__()

            def __dlpack_device__(self):
                return self.a.__dlpack_device__()

        class ArrayOnly:  # only NumPy's __array__ protocol
            def __init__(self, a):
                self.a = a

            def __array__(self, dtype=None):
                return self.a

        results = []
        for wrap in (lambda a: a, DLPackOnly, ArrayOnly):
            f = seqloc.Filter({"width": 32, "height": 32, "headings": 16, "mgr": False})
            results.append(f.step(wrap(vol), crop_pose=(16.0, 16.0, 0.0)))
        def fields(r):
            return (r.u, r.v, r.grid_heading_deg, r.frame_entropy, r.etu_weight, r.peak_log_belief)
        self.assertEqual(fields(results[0]), fields(results[1]))
        self.assertEqual(fields(results[0]), fields(results[2]))
        # Errors are short and name the argument, never the array's values.
        f = seqloc.Filter({"width": 32, "height": 32, "headings": 16, "mgr": False})
        big = np.zeros((200, 200, 16), np.float32)
        for call in (lambda: f.step("not an array"), lambda: f.step(big, odometry="fast"),
                     lambda: f.step(big, crop_pose=(1.0, 2.0))):
            with self.assertRaises(TypeError) as e:
                call()
            self.assertLess(len(str(e.exception)), 200, str(e.exception)[:300])

    def test_odometry_carries_the_belief(self):
        f = seqloc.Filter({"width": 64, "height": 64, "headings": 32, "mgr": False})
        vol = np.full((15, 15, 32), -30.0, np.float32)
        vol[7, 7, 0] = 0.0  # heading 0: grid north, up the window
        f.step(vol, (0, 0, 0), (32.0, 32.0, 0.0))
        flat = np.zeros((15, 15, 32), np.float32)  # no information: the prediction decides
        r = f.step(flat, (5.0, 0.0, 0.0), (32.0, 32.0, 0.0))
        self.assertAlmostEqual(r.argmax.u, 32.0, delta=0.5)
        self.assertAlmostEqual(r.argmax.v, 22.0, delta=0.5)  # 5 m = 10 cells north

    def test_mgr_needs_the_road_distance(self):
        f = seqloc.Filter({"width": 32, "height": 32, "headings": 8})
        vol = np.zeros((9, 9, 8), np.float32)
        with self.assertRaises(ValueError):
            f.step(vol)
        r = f.step(vol, road_distance=np.zeros((32, 32), np.float32))
        self.assertIsInstance(r, seqloc.FilterResult)
        with self.assertRaises(ValueError):
            f.step(vol, road_distance=np.zeros((16, 32), np.float32))

    def test_bad_volumes_and_settings_raise(self):
        f = seqloc.Filter({"width": 32, "height": 32, "headings": 8, "mgr": False})
        with self.assertRaises(ValueError):
            f.step(np.zeros((9, 9), np.float32))
        bad = np.zeros((9, 9, 8), np.float32)
        bad[1, 2, 3] = np.nan
        with self.assertRaises(ValueError):
            f.step(bad)
        with self.assertRaises(ValueError):
            f.step(np.zeros((9, 9, 8), np.int32))
        with self.assertRaises(KeyError):
            seqloc.Filter({"widht": 32})
        with self.assertRaises(ValueError):
            seqloc.Filter({"width": -1})

    def test_every_filter_setting_is_reachable_by_name(self):
        settings = seqloc.Filter.settings()
        # The four the module once lacked, among the others.
        for name in ("subbin_half_width", "motion_noise_xy_per_m", "motion_noise_deg_per_m", "gps_prior",
                     "mgr_sigma_m", "etu_reference_entropy", "outside_crop_nats"):
            self.assertIn(name, settings)
        self.assertEqual(settings["mgr_sigma_m"][0], 3.0)
        # Each setting set to a value other than its default reads back as set.
        for name, (default, what) in settings.items():
            self.assertTrue(what)
            if isinstance(default, bool):
                value = not default
            elif isinstance(default, int):
                value = {"width": 64, "height": 48, "headings": 32, "threads": 2, "pas_radius": 5,
                         "subbin_half_width": 3, "self_calibration_replay_frames": 8,
                         "self_calibration_shared_lag": 5}[name]
            else:
                value = default * 0.5 if default else 0.5
            config = {"width": 64, "height": 48, "headings": 32}
            config[name] = value
            self.assertEqual(seqloc.Filter(config).config[name], value, name)

    def test_float16_volumes_are_read_in_place(self):
        f = seqloc.Filter({"width": 32, "height": 32, "headings": 8, "mgr": False})
        vol = np.full((9, 9, 8), -20.0, np.float16)
        vol[4, 6, 2] = 0.0
        r = f.step(vol, crop_pose=(16.0, 16.0, 0.0))
        self.assertAlmostEqual(r.argmax.u, 18.0)
        self.assertAlmostEqual(r.argmax.v, 16.0)
        self.assertAlmostEqual(r.argmax.grid_heading_deg, 90.0)


class LocalizerAsLocalize(unittest.TestCase):
    """seqloc.Localizer fed a route's volumes in a Python loop gives seqloc localize's poses."""

    @staticmethod
    def write_route(d, frames=12, truth=False, nhw=False):
        """A route of .npy volumes with lat/lon crops: a peak (with noise) that drives east 5 m a
        frame from near the region's centre, crops off the truth by a few metres. With `truth`,
        frames.csv has the ground truth; with `nhw`, the volumes are stored headings first."""
        cache = seqloc.Cache(CACHE)
        x0, y0 = cache.to_grid(cache.info.centre_lat, cache.info.centre_lon)
        rng = np.random.default_rng(7)
        route = os.path.join(d, "route")
        os.makedirs(route)
        with open(os.path.join(route, "route.json"), "w") as f:
            layout = ', "layout": "NHW"' if nhw else ""
            f.write('{"format": "seqloc-route", "version": 1, "name": "py"' + layout + "}")
        rows = []
        for t in range(frames):
            x, y = x0 + 5.0 * t, y0 + 0.25
            dx, dy = rng.integers(-6, 7, size=2)  # the crop is off the truth by whole cells
            crop_lat, crop_lon = cache.from_grid(x - 0.5 * dx, y - 0.5 * dy)
            vol = (rng.normal(0.0, 1.0, (31, 31, 64)) - 6.0).astype(np.float32)
            vol[15 - dy, 15 + dx, 16] = 0.0  # east: compass 90 degrees, bin 16 of 64
            np.save(os.path.join(route, f"v{t}.npy"), vol.transpose(2, 0, 1).copy() if nhw else vol)
            row = (f"f{t}", float(t), f"v{t}.npy", f"{crop_lat:.12f}", f"{crop_lon:.12f}", 5.0 if t else 0.0, 0.0, 0.0)
            if truth:
                row += tuple(f"{c:.12f}" for c in cache.from_grid(x, y)) + (90.0,)
            rows.append(row)
        with open(os.path.join(route, "frames.csv"), "w", newline="") as f:
            w = csv.writer(f)
            w.writerow(["frame", "timestamp", "volume", "crop_lat", "crop_lon", "odo_forward_m", "odo_left_m",
                        "odo_yaw_deg"] + (["gt_lat", "gt_lon", "gt_heading_deg"] if truth else []))
            w.writerows(rows)
        return route, rows

    @unittest.skipUnless(SEQLOC, "SEQLOC_BINARY not set")
    def test_a_numpy_loop_gives_the_poses_of_seqloc_localize(self):
        with tempfile.TemporaryDirectory() as d:
            route, rows = self.write_route(d)
            out = os.path.join(d, "out")
            for mode in ("seqloc", "online"):
                r = subprocess.run([SEQLOC, "localize", CACHE, route, "-o", out, "--overwrite", "--window", "96",
                                    "--headings", "64", "--mode", mode], capture_output=True, text=True)
                self.assertEqual(r.returncode, 0, r.stderr)
                with open(os.path.join(out, "py", mode, "poses.csv")) as f:
                    expected = list(csv.DictReader(f))
                loc = seqloc.Localizer(CACHE, {"width": 96, "height": 96, "headings": 64}, mode=mode)
                for row, want in zip(rows, expected):
                    vol = np.load(os.path.join(route, row[2]))
                    got = loc.step(vol, (row[5], row[6], row[7]), crop_lat=float(row[3]), crop_lon=float(row[4]))
                    where = f"{mode} frame {want['frame']}"
                    self.assertAlmostEqual(got.lat, float(want["lat"]), places=8, msg=where)
                    self.assertAlmostEqual(got.lon, float(want["lon"]), places=8, msg=where)
                    self.assertAlmostEqual(got.x_m, float(want["x_m"]), delta=0.002, msg=where)
                    self.assertAlmostEqual(got.y_m, float(want["y_m"]), delta=0.002, msg=where)
                    self.assertAlmostEqual(got.heading_deg, float(want["heading_deg"]), delta=0.002, msg=where)
                    self.assertAlmostEqual(got.entropy, float(want["entropy"]), delta=2e-6, msg=where)
                    self.assertAlmostEqual(got.volume_power, float(want["volume_power"]), delta=2e-6, msg=where)
                    self.assertEqual(int(got.relocalized), int(want["relocalized"]), where)
                self.assertEqual(len(expected), len(rows))
                marginal = loc.belief_marginal()
                self.assertEqual(marginal.shape, (96, 96))
                self.assertAlmostEqual(float(marginal.sum()), 1.0, places=4)

    def test_the_torch_loop_with_the_crop_object_near_the_region_edge(self):
        # docs/python.md's loop: a volume made in the frame of the crop Cache.crop returns (grid
        # north, as its cells), stepped with crop=crop, 150 m from the region's east edge where the
        # meridian convergence is largest. The vehicle drives west along grid heading 270 (a bin
        # centre), 4 m a frame; the poses must be the truth, the headings the compass heading 270
        # minus the bearing of true north in the grid there. (Monaco's convergence is 0.014 degrees
        # there: too small for the mix-up crop_lat/crop_lon would make to show in these poses. The
        # test holds crop='s frame and its checks, not the size of the mix-up.)
        try:
            import torch
            as_tensor = torch.from_numpy
        except ImportError:
            as_tensor = np.asarray
        cache = seqloc.Cache(CACHE)
        min_x, min_y, max_x, max_y = cache.info.extent
        x0, y0 = max_x - 150.0, (min_y + max_y) / 2
        lat, lon = cache.from_grid(x0, y0)
        north = cache.to_grid(lat + 1e-3, lon)
        true_north_bearing = math.degrees(math.atan2(north[0] - x0, north[1] - y0))
        bins, grid_heading = 64, 270.0
        loc = seqloc.Localizer(CACHE, {"width": 96, "height": 96, "headings": bins})
        rng = np.random.default_rng(3)
        for t in range(8):
            x, y = x0 - 4.0 * t, y0
            crop = cache.crop(x=x + rng.uniform(-3, 3), y=y + rng.uniform(-3, 3), size_m=32.0)
            n = crop.classes.shape[0]
            c = (np.arange(n) - (n - 1) / 2) * crop.cell_m
            east = crop.crop_x + c[None, :] - x      # (v, u): metres east of the truth
            south = y - (crop.crop_y - c[:, None])   # and south of it
            k = np.arange(bins)
            dk = np.minimum(np.abs(k - grid_heading * bins / 360), bins - np.abs(k - grid_heading * bins / 360))
            volume = (-(east**2 + south**2)[:, :, None] / 2.0 - (dk**2)[None, None, :] / 2.0).astype(np.float32)
            pose = loc.step(as_tensor(volume), (4.0 if t else 0.0, 0.0, 0.0), crop=crop)
            self.assertLess(math.hypot(pose.x_m - x, pose.y_m - y), 0.5, f"frame {t}")
            want = (grid_heading - true_north_bearing) % 360
            self.assertAlmostEqual((pose.heading_deg - want + 180) % 360 - 180, 0.0, delta=0.01, msg=f"frame {t}")
        self.assertNotEqual(true_north_bearing, 0.0)
        # The crop is given alone, and from this localizer's cache.
        with self.assertRaises(seqloc.UsageTypeError):
            loc.step(volume, (4.0, 0.0, 0.0), crop=crop, crop_lat=lat, crop_lon=lon)
        with self.assertRaises(seqloc.UsageTypeError):
            loc.step(volume, (4.0, 0.0, 0.0), crop=(x, y))
        with tempfile.TemporaryDirectory() as d:
            other = os.path.join(d, "copy.gpkg")
            shutil.copyfile(CACHE, other)
            with self.assertRaisesRegex(seqloc.UsageError, "not from this localizer's cache"):
                loc.step(volume, (4.0, 0.0, 0.0), crop=seqloc.Cache(other).crop(x=x, y=y, size_m=32.0))

    @unittest.skipUnless(SEQLOC, "SEQLOC_BINARY not set")
    def test_a_lagged_loop_gives_the_poses_of_seqloc_localize_with_that_lag(self):
        with tempfile.TemporaryDirectory() as d:
            route, rows = self.write_route(d, frames=10)
            out = os.path.join(d, "out")
            r = subprocess.run([SEQLOC, "localize", CACHE, route, "-o", out, "--window", "96", "--headings", "64",
                                "--lag", "3"], capture_output=True, text=True)
            self.assertEqual(r.returncode, 0, r.stderr)
            with open(os.path.join(out, "py", "seqloc", "poses.csv")) as f:
                expected = list(csv.DictReader(f))
            loc = seqloc.Localizer(CACHE, {"width": 96, "height": 96, "headings": 64}, lag=3)
            self.assertEqual(loc.lag, 3)
            final = []
            for t, row in enumerate(rows):
                pose = loc.step(np.load(os.path.join(route, row[2])), (row[5], row[6], row[7]),
                                crop_lat=float(row[3]), crop_lon=float(row[4]))
                self.assertEqual((pose.index, pose.frame), (t, str(t)))
                # Frame t - 3 is final once frame t is in.
                ready = loc.final_poses()
                self.assertEqual([p.index for p in ready], [t - 3] if t >= 3 else [])
                final += ready
            final += loc.finish()
            self.assertEqual([p.index for p in final], list(range(len(rows))))
            for got, want in zip(final, expected):
                self.assertAlmostEqual(got.x_m, float(want["x_m"]), delta=0.002, msg=want["frame"])
                self.assertAlmostEqual(got.y_m, float(want["y_m"]), delta=0.002, msg=want["frame"])
                self.assertAlmostEqual(got.heading_deg, float(want["heading_deg"]), delta=0.002, msg=want["frame"])
            with self.assertRaises(ValueError):
                seqloc.Localizer(CACHE, lag=-1)

    def test_the_cuda_backend_gives_the_cpu_poses_or_says_why_it_cannot_run(self):
        status = seqloc.cuda_status()
        self.assertEqual(set(status), {"built", "usable", "reason", "device"})
        with self.assertRaises(ValueError):
            seqloc.Localizer(CACHE, device="tpu")
        if not status["usable"]:
            self.assertTrue(status["reason"])
            with self.assertRaises(seqloc.IOError) as refused:
                seqloc.Localizer(CACHE, device="cuda")
            self.assertIn(status["reason"], str(refused.exception))
        if not status["built"]:
            with self.assertRaises(seqloc.IOError):
                seqloc.Localizer(CACHE, device="cuda-host")
            return
        # The CUDA kernels run on the CPU ("cuda-host"; "cuda" as well where a GPU is usable): the
        # CPU filter's poses, frame for frame.
        devices = ["cuda-host"] + (["cuda"] if status["usable"] else [])
        with tempfile.TemporaryDirectory() as d:
            route, rows = self.write_route(d, frames=8)
            config = {"width": 96, "height": 96, "headings": 64}
            localizers = {name: seqloc.Localizer(CACHE, config, device=name) for name in ["cpu"] + devices}
            for row in rows:
                vol = np.load(os.path.join(route, row[2]))
                poses = {name: loc.step(vol, (row[5], row[6], row[7]), crop_lat=float(row[3]), crop_lon=float(row[4]))
                         for name, loc in localizers.items()}
                for name in devices:
                    where = f"{name} frame {row[0]}"
                    self.assertAlmostEqual(poses[name].x_m, poses["cpu"].x_m, delta=0.01, msg=where)
                    self.assertAlmostEqual(poses[name].y_m, poses["cpu"].y_m, delta=0.01, msg=where)
                    self.assertAlmostEqual(poses[name].heading_deg, poses["cpu"].heading_deg, delta=0.01, msg=where)
                    self.assertAlmostEqual(poses[name].volume_power, poses["cpu"].volume_power, delta=1e-5, msg=where)

    @unittest.skipUnless(SEQLOC, "SEQLOC_BINARY not set")
    def test_a_pytorch_loop_gives_the_poses_of_seqloc_localize(self):
        try:
            import torch  # python3-torch, Debian's (scripts/deps test installs it)
        except ImportError:
            self.skipTest("python3-torch is not installed")
        with tempfile.TemporaryDirectory() as d:
            route, rows = self.write_route(d, frames=8)
            out = os.path.join(d, "out")
            r = subprocess.run([SEQLOC, "localize", CACHE, route, "-o", out, "--window", "96", "--headings", "64"],
                               capture_output=True, text=True)
            self.assertEqual(r.returncode, 0, r.stderr)
            with open(os.path.join(out, "py", "seqloc", "poses.csv")) as f:
                expected = list(csv.DictReader(f))
            loc = seqloc.Localizer(CACHE, {"width": 96, "height": 96, "headings": 64})
            with torch.no_grad():
                for row, want in zip(rows, expected):
                    # What a backbone's output looks like: a CPU tensor, log-softmax over all cells.
                    logits = torch.from_numpy(np.load(os.path.join(route, row[2])))
                    log_probs = torch.log_softmax(logits.reshape(-1), 0).reshape(logits.shape)
                    pose = loc.step(log_probs, (row[5], row[6], row[7]), crop_lat=float(row[3]),
                                    crop_lon=float(row[4]))
                    self.assertAlmostEqual(pose.x_m, float(want["x_m"]), delta=0.002, msg=want["frame"])
                    self.assertAlmostEqual(pose.y_m, float(want["y_m"]), delta=0.002, msg=want["frame"])
                    self.assertAlmostEqual(pose.heading_deg, float(want["heading_deg"]), delta=0.002,
                                           msg=want["frame"])

    @unittest.skipUnless(SEQLOC, "SEQLOC_BINARY not set")
    def test_a_calibration_file_applies_as_localize_applies_it(self):
        with tempfile.TemporaryDirectory() as d:
            route, rows = self.write_route(d, frames=6)
            calibration = os.path.join(d, "calibration.json")
            with open(calibration, "w") as f:
                f.write('{"format": "seqloc-calibration", "version": 1, "temperature": 2.0, "blur_cells": 1.0, '
                        '"blur_bins": 0.0, "floor": 0.1}')
            out = os.path.join(d, "out")
            r = subprocess.run([SEQLOC, "localize", CACHE, route, "-o", out, "--window", "96", "--headings", "64",
                                "--calibration", calibration], capture_output=True, text=True)
            self.assertEqual(r.returncode, 0, r.stderr)
            with open(os.path.join(out, "py", "seqloc", "poses.csv")) as f:
                expected = list(csv.DictReader(f))
            loc = seqloc.Localizer(CACHE, {"width": 96, "height": 96, "headings": 64}, calibration=calibration)
            plain = seqloc.Localizer(CACHE, {"width": 96, "height": 96, "headings": 64})
            differs = False
            for row, want in zip(rows, expected):
                vol = np.load(os.path.join(route, row[2]))
                got = loc.step(vol, (row[5], row[6], row[7]), crop_lat=float(row[3]), crop_lon=float(row[4]))
                other = plain.step(vol, (row[5], row[6], row[7]), crop_lat=float(row[3]), crop_lon=float(row[4]))
                self.assertAlmostEqual(got.x_m, float(want["x_m"]), delta=0.002, msg=want["frame"])
                self.assertAlmostEqual(got.y_m, float(want["y_m"]), delta=0.002, msg=want["frame"])
                self.assertAlmostEqual(got.entropy, float(want["entropy"]), delta=2e-6, msg=want["frame"])
                differs = differs or abs(got.entropy - other.entropy) > 1e-3
            self.assertTrue(differs, "the calibration must change the frames")
            with open(calibration, "w") as f:
                f.write('{"format": "seqloc-calibration", "version": 2}')
            with self.assertRaisesRegex(ValueError, "calibration.json"):
                seqloc.Localizer(CACHE, calibration=calibration)
            with self.assertRaises(seqloc.DataError):  # the file's fault: its category's class
                seqloc.Localizer(CACHE, calibration=calibration)

    def test_every_misuse_is_a_seqloc_error_and_the_builtin_it_was(self):
        # docs/python.md: every exception the module raises is a seqloc.Error; usage errors stay
        # the built-in a handler catches for them (ValueError, TypeError, KeyError, IndexError).
        cache = seqloc.Cache(CACHE)
        lat, lon = cache.info.centre_lat, cache.info.centre_lon
        f = seqloc.Filter({"width": 32, "height": 32, "headings": 8, "mgr": False})
        loc = seqloc.Localizer(CACHE, {"width": 64, "height": 64, "headings": 16})
        vol = np.zeros((9, 9, 16), np.float32)
        with tempfile.TemporaryDirectory() as d:
            route = seqloc.Route(LocalizerAsLocalize.write_route(d, frames=2)[0])
            cases = [
                ("mode", lambda: seqloc.Localizer(CACHE, mode="offline"), ValueError),
                ("lag", lambda: seqloc.Localizer(CACHE, lag=-1), ValueError),
                ("device", lambda: seqloc.Localizer(CACHE, device="tpu"), ValueError),
                ("preset", lambda: seqloc.Filter({"preset": "fast"}), ValueError),
                ("setting", lambda: seqloc.Filter({"widht": 32}), KeyError),
                ("layer", lambda: cache.crop(lat, lon, 32.0, layers=["roads"]), ValueError),
                ("both points", lambda: cache.crop(lat, lon, 32.0, x=1.0, y=2.0), TypeError),
                ("not an array", lambda: f.step("not an array"), TypeError),
                ("shape", lambda: f.step(np.zeros((9, 9), np.float32)), ValueError),
                ("dtype", lambda: f.step(np.zeros((9, 9, 8), np.int32)), ValueError),
                ("no crop", lambda: loc.step(vol), TypeError),
                ("frame index", lambda: route[5], IndexError),
            ]
            for name, call, builtin in cases:
                with self.assertRaises(builtin, msg=name) as raised:
                    call()
                self.assertIsInstance(raised.exception, seqloc.Error, name)

    def test_bad_arguments_are_short_errors(self):
        with self.assertRaises(ValueError):
            seqloc.Localizer(CACHE, mode="offline")
        loc = seqloc.Localizer(CACHE, {"width": 64, "height": 64, "headings": 16})
        vol = np.zeros((9, 9, 16), np.float32)
        with self.assertRaises(TypeError):
            loc.step(vol)  # no crop
        with self.assertRaises(TypeError):
            loc.step(vol, crop_lat=1.0, crop_x=2.0, crop_y=3.0)


class RouteAndRunFolders(unittest.TestCase):
    """seqloc.Route reads a route folder as localize does; Localizer.step_frame steps its frames
    as localize does; seqloc.RunFolder reads localize's output back (io's one reader of each)."""

    def test_a_route_reads_back_what_was_written(self):
        for nhw in (False, True):
            with tempfile.TemporaryDirectory() as d:
                path, rows = LocalizerAsLocalize.write_route(d, frames=4, truth=True, nhw=nhw)
                route = seqloc.Route(path)
                self.assertEqual((route.name, len(route), route.layout), ("py", 4, "NHW" if nhw else "HWN"))
                self.assertFalse(route.probabilities)
                self.assertEqual(route.cell_m, 0.5)
                for frame, row in zip(route, rows):
                    self.assertEqual((frame.frame, frame.timestamp_s, frame.line), (row[0], row[1], frame.index + 2))
                    self.assertEqual(frame.odometry, (row[5], row[6], row[7]))
                    self.assertAlmostEqual(frame.crop_lat, float(row[3]), places=12)
                    self.assertAlmostEqual(frame.crop_lon, float(row[4]), places=12)
                    self.assertIsNone(frame.crop_x)
                    self.assertIsNone(frame.gps)
                    self.assertAlmostEqual(frame.truth[0], float(row[8]), places=12)
                    self.assertEqual(frame.truth[2], 90.0)
                    volume = frame.read_volume()
                    stored = np.load(frame.volume_path)
                    np.testing.assert_array_equal(volume, stored.transpose(1, 2, 0) if nhw else stored)
                    self.assertEqual(volume.shape, (31, 31, 64))
                    self.assertFalse(volume.flags.writeable)  # the mapped file, read-only
                self.assertEqual(route[-1].frame, "f3")
                with self.assertRaises(IndexError):
                    route[4]

    def test_a_bad_route_raises_data_error_naming_the_line(self):
        with tempfile.TemporaryDirectory() as d:
            path, _ = LocalizerAsLocalize.write_route(d, frames=3)
            with open(os.path.join(path, "frames.csv"), "a") as f:
                f.write("f9,not-a-time,v0.npy,1,2,0,0,0\n")
            with self.assertRaisesRegex(seqloc.DataError, "frames.csv:5"):
                seqloc.Route(path)
        with self.assertRaises(seqloc.Error):
            seqloc.Route("/nonexistent-route")

    def check_local_frame(self, pose):
        """Pose.local_frame as docs/ros.md has it: at its own position as origin the pose sits at
        (0, 0, 0), its yaw is 90 degrees less its compass heading, and its covariance is the grid's
        turned clockwise by the convergence (heading_deg - grid_heading_deg)."""
        local = pose.local_frame(pose.lat, pose.lon)
        for v in local["position_m"]:
            self.assertAlmostEqual(v, 0, delta=1e-6)
        yaw = math.degrees(local["yaw_rad"])
        self.assertAlmostEqual((yaw - (90 - pose.heading_deg) + 180) % 360 - 180, 0, delta=1e-9)
        g = math.radians(pose.heading_deg - pose.grid_heading_deg)
        c, s = math.cos(g), math.sin(g)
        (xx, xy), (_, yy) = pose.covariance_m2
        ee = c * c * xx + 2 * c * s * xy + s * s * yy
        en = -c * s * xx + (c * c - s * s) * xy + c * s * yy
        nn = s * s * xx - 2 * c * s * xy + c * c * yy
        for got in (local["fix_covariance_m2"], local["covariance_m2"]):
            for a, b in zip(sum(got, ()), (ee, en, en, nn)):
                self.assertAlmostEqual(a, b, delta=1e-9 * max(1.0, abs(b)))

    @unittest.skipUnless(SEQLOC, "SEQLOC_BINARY not set")
    def test_step_frame_gives_localize_poses_and_the_run_folder_reads_them(self):
        for nhw, lag in ((False, 0), (True, 2)):
            with tempfile.TemporaryDirectory() as d:
                path, _ = LocalizerAsLocalize.write_route(d, frames=8, truth=True, nhw=nhw)
                out = os.path.join(d, "out")
                r = subprocess.run([SEQLOC, "localize", CACHE, path, "-o", out, "--window", "96", "--headings",
                                    "64", "--lag", str(lag), "--mode", "seqloc"], capture_output=True, text=True)
                self.assertEqual(r.returncode, 0, r.stderr)
                run = seqloc.RunFolder(out)
                self.assertEqual((run.routes(), run.modes("py")), (["py"], ["seqloc"]))
                expected = run.poses("py", "seqloc")
                with open(os.path.join(out, "py", "seqloc", "poses.csv")) as f:
                    rows = list(csv.DictReader(f))
                self.assertEqual([p.frame for p in expected], [row["frame"] for row in rows])
                self.assertEqual([p.heading_deg for p in expected], [float(row["heading_deg"]) for row in rows])
                self.assertIsNone(expected[0].grid_heading_deg)

                loc = seqloc.Localizer(CACHE, {"width": 96, "height": 96, "headings": 64}, lag=lag)
                got = []
                for frame in seqloc.Route(path):
                    pose = loc.step_frame(frame)
                    self.assertEqual((pose.index, pose.frame), (frame.index, frame.frame))
                    got += [pose] if lag == 0 else loc.final_poses()
                got += loc.finish()
                self.assertEqual([p.frame for p in got], [p.frame for p in expected])
                for g, want in zip(got, expected):
                    self.assertAlmostEqual(g.x_m, want.x_m, delta=0.002, msg=want.frame)
                    self.assertAlmostEqual(g.y_m, want.y_m, delta=0.002, msg=want.frame)
                    self.assertAlmostEqual(g.heading_deg, want.heading_deg, delta=0.002, msg=want.frame)
                    self.assertAlmostEqual(g.position_error_m, want.position_error_m, delta=0.002, msg=want.frame)
                    self.assertIsNotNone(g.grid_heading_deg)
                    # The uncertainty (filtered, or with a lag the smoothed posterior's) as poses.csv has it.
                    for a, b in zip(sum(g.covariance_m2, ()), sum(want.covariance_m2, ())):
                        self.assertAlmostEqual(a, b, delta=1e-4 * max(1.0, abs(b)), msg=want.frame)
                    self.assertGreater(g.covariance_m2[0][0], 0, want.frame)
                    self.assertAlmostEqual(g.heading_sd_deg, want.heading_sd_deg, delta=1e-3, msg=want.frame)
                    self.assertAlmostEqual(g.mass_within_5m, want.mass_within_5m, delta=1e-4, msg=want.frame)
                    self.assertEqual(g.multimodal, want.multimodal, want.frame)
                    self.check_local_frame(g)
                with self.assertRaises(seqloc.UsageError):  # poses.csv keeps no grid heading
                    expected[0].local_frame(expected[0].lat, expected[0].lon)

                # The run's metrics are seqloc evaluate's, recomputed here from the errors.
                metrics = run.evaluate()
                self.assertEqual(list(metrics), ["seqloc"])
                m = metrics["seqloc"]
                errors = [p.position_error_m for p in expected]
                self.assertEqual(m.frames, len(errors))
                self.assertAlmostEqual(m.position_recall[2], 100.0 * sum(e <= 5.0 for e in errors) / len(errors))
                self.assertAlmostEqual(m.mean_position_error_m, sum(errors) / len(errors), delta=1e-3)
                with self.assertRaises(seqloc.UsageError):
                    run.poses("py", "best")
                with self.assertRaises(seqloc.DataError):
                    run.poses("py", "smooth")


class TypingStub(unittest.TestCase):
    """python/seqloc/_seqloc.pyi names every class, member and parameter the module has."""

    def test_the_stub_matches_the_module(self):
        import ast
        import inspect
        import re

        stub_path = os.path.join(os.path.dirname(seqloc.__file__), "_seqloc.pyi")
        tree = ast.parse(open(stub_path).read())
        stub_classes = {n.name: n for n in tree.body if isinstance(n, ast.ClassDef) and not n.name.startswith("_")}
        # Names of a class under another name (the earlier error names): NAME = CLASS.
        stub_aliases = {n.targets[0].id: n.value.id for n in tree.body
                        if isinstance(n, ast.Assign) and isinstance(n.value, ast.Name) and n.value.id in stub_classes}
        module = seqloc._seqloc
        runtime_classes = {name for name, v in vars(module).items() if inspect.isclass(v)}
        self.assertEqual(set(stub_classes) | set(stub_aliases), runtime_classes)
        for alias, name in stub_aliases.items():
            self.assertIs(getattr(module, alias), getattr(module, name), alias)
        stub_functions = {n.name for n in tree.body if isinstance(n, ast.FunctionDef)}
        runtime_functions = {name for name, v in vars(module).items()
                             if inspect.isbuiltin(v) and not name.startswith("_")}
        self.assertEqual(stub_functions, runtime_functions)
        self.assertEqual(set(seqloc.__all__), runtime_classes | runtime_functions)
        for name, node in stub_classes.items():
            cls = getattr(module, name)
            if issubclass(cls, BaseException):
                continue
            stubbed = {n.name: n for n in node.body if isinstance(n, ast.FunctionDef)}
            public = {m for m in dir(cls) if not m.startswith("_")}
            # A constructor is one with a signature (pybind11 gives the others one that raises).
            public |= {m for m in ("__init__", "__len__", "__getitem__", "__iter__")
                       if m in vars(cls) and (getattr(cls, m).__doc__ or "").startswith(m + "(")}
            self.assertEqual(set(stubbed), public, name)
            for member, fn in stubbed.items():
                attribute = inspect.getattr_static(cls, member)
                if isinstance(attribute, property):
                    self.assertTrue(any(isinstance(d, ast.Name) and d.id == "property" for d in fn.decorator_list),
                                    f"{name}.{member} is a property")
                    continue
                # pybind11's signature line: "name(self: ..., a: ..., *, b: ...) -> ..."; overloads: the first.
                doc = getattr(cls, member).__doc__ or ""
                line = next(l for l in doc.splitlines() if l.startswith(member + "("))
                params = re.findall(r"(?:\(|, )(\*|\w+)(?=[:,)]|$)", line[len(member):line.rindex(") ->")])
                stub_params = [a.arg for a in fn.args.args] + (["*"] if fn.args.kwonlyargs else [])
                stub_params += [a.arg for a in fn.args.kwonlyargs]
                self.assertEqual(params, stub_params, f"{name}.{member}")


if __name__ == "__main__":
    unittest.main()
