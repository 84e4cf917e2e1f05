"""`seqloc serve` and `seqloc export` checked with GDAL's own drivers: GDAL's WMTS client reads the
served tiles, GDAL's GeoTIFF driver reads served crops and exported COGs, GDAL's VRT driver reads the
exported VRT; each is compared with GDAL's GeoPackage driver reading the cache itself."""

import argparse
import json
import math
import os
import subprocess
import sys
import tempfile
import threading
import unittest
import urllib.error
import urllib.request

import numpy as np
from osgeo import gdal

gdal.UseExceptions()
ARGS = None


def gpkg_window(table, x0, y0, w, h):
    ds = gdal.Open(f"GPKG:{ARGS.cache}:{table}")
    return [ds.GetRasterBand(b + 1).ReadAsArray(x0, y0, w, h) for b in range(ds.RasterCount)], ds.GetGeoTransform()


class Served(unittest.TestCase):
    @classmethod
    def setUpClass(cls):
        cls.server = subprocess.Popen([ARGS.seqloc, "serve", ARGS.cache, "--port", "0", "--web", ARGS.web],
                                      stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
        line = cls.server.stdout.readline()
        assert line.startswith("seqloc serve: http://"), line
        cls.base = line.split()[2].rstrip("/")
        cls.region = os.path.splitext(os.path.basename(ARGS.cache))[0]

    @classmethod
    def tearDownClass(cls):
        cls.server.terminate()
        cls.server.wait(timeout=20)
        # A clean stop on SIGTERM: exit code 0 and a summary line.
        assert cls.server.returncode == 0, cls.server.returncode

    def get(self, path):
        with urllib.request.urlopen(self.base + path, timeout=30) as r:
            return r.status, dict(r.headers), r.read()

    def test_gdal_wmts_client_reads_the_cache_exactly(self):
        url = f"WMTS:{self.base}/regions/{self.region}/wmts.xml,layer=classes"
        ds = gdal.Open(url)
        ref_bands, ref_gt = gpkg_window("classes", 0, 0, 1, 1)
        self.assertEqual(ds.GetGeoTransform(), ref_gt)
        ref = gdal.Open(f"GPKG:{ARGS.cache}:classes")
        self.assertEqual((ds.RasterXSize, ds.RasterYSize), (ref.RasterXSize, ref.RasterYSize))
        # A window across tile corners.
        x0, y0, w, h = 400, 300, 700, 600
        for b in range(3):
            np.testing.assert_array_equal(ds.GetRasterBand(b + 1).ReadAsArray(x0, y0, w, h),
                                          ref.GetRasterBand(b + 1).ReadAsArray(x0, y0, w, h))

    def test_gdal_wmts_reads_distances_and_priors_as_data(self):
        # GDAL's WMTS client takes any layer as 4 bands of Byte; the service description the
        # server offers per layer makes it read the GeoTIFF tiles as Float32 metres.
        ref = gdal.Open(f"GPKG:{ARGS.cache}:road_distance")
        w, h = 700, 600  # around the centre, across tile corners
        x0, y0 = ref.RasterXSize // 2 - 300, ref.RasterYSize // 2 - 200
        expected = ref.GetRasterBand(1).ReadAsArray(x0, y0, w, h)
        self.assertGreater(np.ptp(expected), 10.0)  # a window with roads and fields, not a constant
        _, headers, description = self.get(f"/regions/{self.region}/wmts/road_distance.xml")
        self.assertIn("application/xml", headers["Content-Type"])
        ds = gdal.Open(description.decode())
        self.assertEqual(ds.RasterCount, 1)
        self.assertEqual(gdal.GetDataTypeName(ds.GetRasterBand(1).DataType), "Float32")
        self.assertEqual(ds.GetGeoTransform(), ref.GetGeoTransform())
        np.testing.assert_allclose(ds.GetRasterBand(1).ReadAsArray(x0, y0, w, h), expected, atol=1e-4)
        # The prior is exp(-d^2 / (2 sigma^2)) of those distances (tilejson gives sigma).
        sigma = json.loads(self.get(f"/regions/{self.region}/tilejson.json")[2])["road_prior_sigma_m"]
        prior = gdal.Open(self.get(f"/regions/{self.region}/wmts/road_prior.xml")[2].decode())
        np.testing.assert_allclose(prior.GetRasterBand(1).ReadAsArray(x0, y0, w, h),
                                   np.exp(-expected.astype(np.float64) ** 2 / (2 * sigma ** 2)), atol=1e-5)
        with self.assertRaises(urllib.error.HTTPError) as e:
            self.get(f"/regions/{self.region}/wmts/roads.xml")
        self.assertEqual(e.exception.code, 404)

    def xyz_tile_at_centre(self, zoom):
        """The XYZ tile holding a point near the region's centre, and its EPSG:3857 bounds."""
        info = json.loads(self.get(f"/regions/{self.region}/tilejson.json")[2])
        lon, lat = info["center"][0], info["center"][1]
        n = 2 ** zoom
        x = int((lon + 180.0) / 360.0 * n)
        y = int((1.0 - math.asinh(math.tan(math.radians(lat))) / math.pi) / 2.0 * n)
        half = 20037508.342789244
        size = 2 * half / n
        west, north = -half + x * size, half - y * size
        return x, y, (west, north - size, west + size, north)

    def tms_description(self, layer, zoom, bands, data_type):
        """GDAL's TMS minidriver over the server's XYZ tiles of one layer (data style)."""
        url = f"{self.base}/regions/{self.region}/xyz/{layer}/${{z}}/${{x}}/${{y}}.png?style=data"
        return (f"<GDAL_WMS><Service name=\"TMS\"><ServerUrl>{url}</ServerUrl></Service>"
                "<DataWindow><UpperLeftX>-20037508.342789244</UpperLeftX><UpperLeftY>20037508.342789244</UpperLeftY>"
                "<LowerRightX>20037508.342789244</LowerRightX><LowerRightY>-20037508.342789244</LowerRightY>"
                f"<TileLevel>{zoom}</TileLevel><TileCountX>1</TileCountX><TileCountY>1</TileCountY>"
                "<YOrigin>top</YOrigin></DataWindow><Projection>EPSG:3857</Projection>"
                f"<BlockSizeX>256</BlockSizeX><BlockSizeY>256</BlockSizeY><BandsCount>{bands}</BandsCount>"
                f"<DataType>{data_type}</DataType></GDAL_WMS>")

    def test_xyz_tiles_are_gdalwarp_of_the_cache(self):
        info = json.loads(self.get(f"/regions/{self.region}/tilejson.json")[2])
        self.assertEqual(info["tilejson"], "3.0.0")
        self.assertEqual(info["tiles"][0], f"{self.base}/regions/{self.region}/xyz/classes/{{z}}/{{x}}/{{y}}.png")
        zmin, zmax = info["minzoom"], info["maxzoom"]
        # The highest zoom's pixels are about the 0.5 m cells at this latitude.
        pixel_m = 2 * 20037508.342789244 / 256 / 2 ** zmax * math.cos(math.radians(info["center"][1]))
        self.assertTrue(0.5 / math.sqrt(2) <= pixel_m <= 0.5 * math.sqrt(2), pixel_m)
        self.assertLess(zmin, zmax)
        self.assertEqual(len(info["bounds"]), 4)
        for zoom in (zmax, zmin + 1):
            x, y, te = self.xyz_tile_at_centre(zoom)
            # GDAL's TMS reader against gdalwarp of the GeoPackage itself, on the tile's grid.
            ds = gdal.Open(self.tms_description("road_distance", zoom, 1, "UInt16"))
            served_cm = ds.GetRasterBand(1).ReadAsArray(x * 256, y * 256, 256, 256)
            ref = gdal.Warp("", gdal.Open(f"GPKG:{ARGS.cache}:road_distance"), format="MEM", dstSRS="EPSG:3857",
                            outputBounds=te, width=256, height=256, resampleAlg="bilinear", outputType=gdal.GDT_Float32)
            expected = ref.GetRasterBand(1).ReadAsArray()
            self.assertGreater(np.ptp(expected), 5.0, "a tile with roads and fields")
            np.testing.assert_allclose(served_cm * 0.01, expected, atol=0.0051, err_msg=f"road_distance zoom {zoom}")
            classes = gdal.Open(self.tms_description("classes", zoom, 3, "Byte"))
            source = gdal.OpenEx(f"GPKG:{ARGS.cache}:classes", open_options=["BAND_COUNT=3"])
            ref = gdal.Warp("", source, format="MEM", dstSRS="EPSG:3857", outputBounds=te, width=256, height=256,
                            resampleAlg="near")
            for b in range(3):
                np.testing.assert_array_equal(classes.GetRasterBand(b + 1).ReadAsArray(x * 256, y * 256, 256, 256),
                                              ref.GetRasterBand(b + 1).ReadAsArray(), err_msg=f"classes zoom {zoom}")
        # @2x: the same ground at 512 px; the picture style by default; outside the zooms, a 404.
        x, y, _ = self.xyz_tile_at_centre(zmax)
        status, headers, body = self.get(f"/regions/{self.region}/xyz/classes/{zmax}/{x}/{y}@2x.png")
        self.assertEqual((status, headers["Content-Type"]), (200, "image/png"))
        with tempfile.NamedTemporaryFile(suffix=".png") as f:
            f.write(body)
            f.flush()
            picture = gdal.Open(f.name)
            self.assertEqual((picture.RasterXSize, picture.RasterYSize, picture.RasterCount), (512, 512, 4))
        for path in (f"/regions/{self.region}/xyz/classes/{zmax + 1}/{2 * x}/{2 * y}.png",
                     f"/regions/{self.region}/xyz/classes/{zmax}/0/0.png"):
            with self.assertRaises(urllib.error.HTTPError) as e:
                self.get(path)
            self.assertEqual(e.exception.code, 404, path)

    def test_served_geotiff_crop_is_georeferenced(self):
        info = json.loads(self.get(f"/regions/{self.region}/tilejson.json")[2])
        lon, lat = info["center"][0] + 0.001, info["center"][1] - 0.0005
        q = f"lat={lat}&lon={lon}&size_m=75&layers=classes,road_distance"
        status, headers, body = self.get(f"/regions/{self.region}/crop?{q}&format=tif")
        self.assertEqual(status, 200)
        sidecar = json.loads(self.get(f"/regions/{self.region}/crop.json?{q}")[2])
        with tempfile.NamedTemporaryFile(suffix=".tif") as f:
            f.write(body)
            f.flush()
            ds = gdal.Open(f.name)
            gt = ds.GetGeoTransform()
            self.assertEqual(list(gt), sidecar["geotransform"])
            self.assertEqual((ds.RasterXSize, ds.RasterYSize, ds.RasterCount), (150, 150, 4))
            ref = gdal.Open(f"GPKG:{ARGS.cache}:classes")
            rgt = ref.GetGeoTransform()
            x0, y0 = round((gt[0] - rgt[0]) / 0.5), round((rgt[3] - gt[3]) / 0.5)
            classes, _ = gpkg_window("classes", x0, y0, 150, 150)
            for b in range(3):
                np.testing.assert_array_equal(ds.GetRasterBand(b + 1).ReadAsArray(), classes[b])
            dist_ds = gdal.Open(f"GPKG:{ARGS.cache}:road_distance")  # kept alive while its band is read
            # GDAL's GeoPackage driver applies the coverage's scale: it reads metres.
            expected = dist_ds.GetRasterBand(1).ReadAsArray(x0, y0, 150, 150)
            np.testing.assert_allclose(ds.GetRasterBand(4).ReadAsArray(), expected, atol=1e-4)
            self.assertEqual(ds.GetRasterBand(4).GetDescription(), "road_distance")
            # The projection GDAL reads is the cache's own.
            srs = ds.GetSpatialRef()
            self.assertTrue(srs.IsSame(ref.GetSpatialRef()))

    def test_parallel_clients_get_identical_answers(self):
        paths = [f"/regions/{self.region}/{layer}/{c}/{r}.{ext}"
                 for layer in ("classes", "road_distance", "road_prior") for ext in ("png", "npy")
                 for c in range(2) for r in range(2)]
        serial = {p: self.get(p)[2] for p in paths}
        errors = []

        def client():
            try:
                for _ in range(3):
                    for p in paths:
                        if self.get(p)[2] != serial[p]:
                            errors.append("different body: " + p)
            except Exception as e:  # noqa: BLE001 - every failure is reported
                errors.append(repr(e))

        threads = [threading.Thread(target=client) for _ in range(8)]
        for t in threads:
            t.start()
        for t in threads:
            t.join()
        self.assertEqual(errors, [])

    def test_errors_are_json(self):
        with self.assertRaises(urllib.error.HTTPError) as e:
            self.get(f"/regions/{self.region}/classes/999/0.png")
        self.assertEqual(e.exception.code, 404)
        self.assertIn("outside", json.loads(e.exception.read())["error"]["message"])

    def test_viewer_page_is_served(self):
        status, headers, body = self.get("/")
        self.assertEqual(status, 200)
        self.assertIn("text/html", headers["Content-Type"])


class Exported(unittest.TestCase):
    def run_seqloc(self, *args):
        return subprocess.run([ARGS.seqloc, *args], capture_output=True, text=True, timeout=600)

    def test_cog_of_a_box_matches_the_cache(self):
        ref = gdal.Open(f"GPKG:{ARGS.cache}:road_distance")
        rgt = ref.GetGeoTransform()
        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "distance.tif")
            info = json.loads(self.run_seqloc("cache", "info", ARGS.cache, "--json").stdout)
            lat, lon = float(info["centre_lat"]), float(info["centre_lon"])
            bbox = f"{lon - 0.004},{lat - 0.003},{lon + 0.004},{lat + 0.003}"
            r = self.run_seqloc("export", ARGS.cache, "--layer", "road_distance", "--bbox", bbox, "-o", out)
            self.assertEqual(r.returncode, 0, r.stderr)
            self.assertEqual(sorted(os.listdir(d)), ["distance.tif"])  # no temporary left behind
            ds = gdal.Open(out)
            self.assertEqual(ds.GetMetadataItem("LAYOUT", "IMAGE_STRUCTURE"), "COG")
            self.assertGreater(ds.GetRasterBand(1).GetOverviewCount(), 0)
            gt = ds.GetGeoTransform()
            x0, y0 = round((gt[0] - rgt[0]) / 0.5), round((rgt[3] - gt[3]) / 0.5)
            self.assertAlmostEqual(gt[0], rgt[0] + x0 * 0.5)
            self.assertAlmostEqual(gt[3], rgt[3] - y0 * 0.5)
            # GDAL's GeoPackage driver applies the coverage's scale: it reads metres. The export
            # holds the cache's centimetres (UInt16) with the scale and unit that make them metres.
            expected = ref.GetRasterBand(1).ReadAsArray(x0, y0, ds.RasterXSize, ds.RasterYSize)
            band = ds.GetRasterBand(1)
            self.assertEqual(gdal.GetDataTypeName(band.DataType), "UInt16")
            self.assertEqual((band.GetScale(), band.GetOffset(), band.GetUnitType()), (0.01, 0.0, "m"))
            self.assertEqual(band.GetDescription(), "road_distance")
            np.testing.assert_allclose(band.ReadAsArray() * band.GetScale(), expected, atol=1e-4)
            # --float: Float32 metres, the same values, no scale.
            out32 = os.path.join(d, "distance32.tif")
            r = self.run_seqloc("export", ARGS.cache, "--layer", "road_distance", "--bbox", bbox, "--float", "-o", out32)
            self.assertEqual(r.returncode, 0, r.stderr)
            ds32 = gdal.Open(out32)  # held: a GDAL band must not outlive its dataset
            band32 = ds32.GetRasterBand(1)
            self.assertEqual(gdal.GetDataTypeName(band32.DataType), "Float32")
            self.assertEqual(band32.GetUnitType(), "m")
            self.assertIn(band32.GetScale(), (None, 1.0))
            np.testing.assert_allclose(band32.ReadAsArray(), expected, atol=1e-4)
            # The box's corners lie inside the exported raster.
            srs = ds.GetSpatialRef()
            self.assertTrue(srs.IsSame(ref.GetSpatialRef()))
            w, h = ds.RasterXSize * 0.5, ds.RasterYSize * 0.5
            self.assertGreater(w, 0.008 * 111000 * 0.7)  # at least the box's width at this latitude
            self.assertGreater(h, 0.006 * 111000 * 0.95)

    def test_classes_cog_and_region_vrt(self):
        ref = gdal.Open(f"GPKG:{ARGS.cache}:classes")
        with tempfile.TemporaryDirectory() as d:
            cog, vrt = os.path.join(d, "classes.tif"), os.path.join(d, "region.vrt")
            r = self.run_seqloc("export", ARGS.cache, "--layer", "classes", "-o", cog)
            self.assertEqual(r.returncode, 0, r.stderr)
            ds = gdal.Open(cog)
            self.assertEqual((ds.RasterXSize, ds.RasterYSize), (ref.RasterXSize, ref.RasterYSize))
            self.assertEqual(ds.RasterCount, 3)
            self.assertEqual(ds.GetGeoTransform(), ref.GetGeoTransform())
            # A window across tile seams and a corner of the region (reading all of it through the
            # GeoPackage driver takes minutes).
            for x0, y0 in ((700, 900), (ds.RasterXSize - 1200, ds.RasterYSize - 1200)):
                for b in range(3):
                    np.testing.assert_array_equal(ds.GetRasterBand(b + 1).ReadAsArray(x0, y0, 1200, 1200),
                                                  ref.GetRasterBand(b + 1).ReadAsArray(x0, y0, 1200, 1200))
            r = self.run_seqloc("export", ARGS.cache, "-o", vrt)
            self.assertEqual(r.returncode, 0, r.stderr)
            v = gdal.Open(vrt)
            self.assertEqual(v.RasterCount, 4)
            self.assertEqual(v.GetGeoTransform(), ref.GetGeoTransform())
            self.assertEqual(v.GetRasterBand(4).GetDescription(), "road_distance")
            dist_ds = gdal.Open(f"GPKG:{ARGS.cache}:road_distance")  # kept alive while its band is read
            dist = dist_ds.GetRasterBand(1).ReadAsArray(0, 0, 800, 800)
            np.testing.assert_array_equal(v.GetRasterBand(4).ReadAsArray(0, 0, 800, 800), dist)
            np.testing.assert_array_equal(v.GetRasterBand(2).ReadAsArray(0, 0, 800, 800),
                                          ref.GetRasterBand(2).ReadAsArray(0, 0, 800, 800))

    def test_bad_exports_fail_cleanly(self):
        with tempfile.TemporaryDirectory() as d:
            out = os.path.join(d, "x.tif")
            r = self.run_seqloc("export", ARGS.cache, "--bbox", "100,10,100.01,10.01", "-o", out)
            self.assertEqual(r.returncode, 1)
            self.assertIn("does not meet the region", r.stderr)
            self.assertEqual(os.listdir(d), [])
            r = self.run_seqloc("export", ARGS.cache, "--layer", "trees", "-o", out)
            self.assertEqual(r.returncode, 2)
            open(out, "w").close()
            r = self.run_seqloc("export", ARGS.cache, "-o", out)
            self.assertEqual(r.returncode, 2)
            self.assertIn("--overwrite", r.stderr)
            self.assertEqual(os.path.getsize(out), 0)  # untouched


if __name__ == "__main__":
    p = argparse.ArgumentParser()
    p.add_argument("--seqloc", required=True)
    p.add_argument("--cache", required=True)
    p.add_argument("--web", required=True)
    ARGS, rest = p.parse_known_args()
    unittest.main(argv=[sys.argv[0], *rest])
