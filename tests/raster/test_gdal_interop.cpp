// GDAL opens the cache as it is: the right CRS, extent and pixel size, and the very values the
// library reads. Runs on a real region (north-bayreuth) built by the pipeline.

#include <cmath>

#include <gdal_priv.h>
#include <gtest/gtest.h>
#include <ogrsf_frmts.h>

#include "seqloc/ingest/preprocess.hpp"
#include "seqloc/raster/cache.hpp"
#include "support/test_support.hpp"

namespace seqloc::raster {
namespace {

class GdalInterop : public ::testing::Test {
 protected:
  static void SetUpTestSuite() {
    GDALAllRegister();
    const auto osm = test::osm_extract("north-bayreuth.osm.pbf");
    if (osm.empty()) return;
    dir_ = new test::ScratchDir();
    ingest::PreprocessOptions options;
    options.input = osm;
    options.output = *dir_ / "nb.gpkg";
    options.bbox = osm::GeoBox{11.535, 50.005, 11.552, 50.016};  // ~1.2 x 1.2 km around a village
    ingest::preprocess_region(options);
    path_ = options.output;
  }
  static void TearDownTestSuite() { delete dir_; }
  void SetUp() override {}
  static inline test::ScratchDir* dir_ = nullptr;
  static inline std::filesystem::path path_;
};

struct DatasetCloser {
  void operator()(GDALDataset* d) const { GDALClose(d); }
};
using Dataset = std::unique_ptr<GDALDataset, DatasetCloser>;

Dataset open_raster(const std::filesystem::path& path, const char* table) {
  const std::string name = "GPKG:" + path.string() + ":" + table;
  return Dataset(GDALDataset::Open(name.c_str(), GDAL_OF_RASTER | GDAL_OF_READONLY));
}

TEST_F(GdalInterop, RasterTablesHaveTheRegionGeoreference) {
  CacheReader reader(path_);
  const auto& m = reader.metadata();
  for (const char* table : {"classes", "road_distance"}) {
    SCOPED_TRACE(table);
    const auto ds = open_raster(path_, table);
    ASSERT_TRUE(ds) << CPLGetLastErrorMsg();
    EXPECT_EQ(ds->GetRasterXSize(), m.grid.width_px());
    EXPECT_EQ(ds->GetRasterYSize(), m.grid.height_px());
    double gt[6];
    ASSERT_EQ(ds->GetGeoTransform(gt), CE_None);
    EXPECT_DOUBLE_EQ(gt[0], m.grid.min_x());
    EXPECT_DOUBLE_EQ(gt[1], 0.5);
    EXPECT_DOUBLE_EQ(gt[2], 0.0);
    EXPECT_DOUBLE_EQ(gt[3], m.grid.max_y());
    EXPECT_DOUBLE_EQ(gt[4], 0.0);
    EXPECT_DOUBLE_EQ(gt[5], -0.5);
    const OGRSpatialReference* srs = ds->GetSpatialRef();
    ASSERT_NE(srs, nullptr);
    OGRSpatialReference expected;
    ASSERT_EQ(expected.importFromProj4(m.projection().proj_string().c_str()), OGRERR_NONE);
    char* proj = nullptr;
    srs->exportToProj4(&proj);
    EXPECT_TRUE(srs->IsSame(&expected)) << (proj ? proj : "");
    CPLFree(proj);
    EXPECT_NEAR(srs->GetProjParm(SRS_PP_LATITUDE_OF_ORIGIN), m.centre_lat, 1e-12);
    EXPECT_NEAR(srs->GetProjParm(SRS_PP_CENTRAL_MERIDIAN), m.centre_lon, 1e-12);
  }
}

TEST_F(GdalInterop, GdalReadsTheValuesTheLibraryReads) {
  CacheReader reader(path_);
  const auto& g = reader.grid();
  const int w = static_cast<int>(g.width_px()), h = static_cast<int>(g.height_px());

  std::vector<std::uint16_t> ours_cm;
  reader.read_road_distance(0, 0, w, h, ours_cm);
  const auto distance = open_raster(path_, "road_distance");
  ASSERT_TRUE(distance);
  std::vector<float> theirs(static_cast<std::size_t>(w) * h);
  ASSERT_EQ(distance->GetRasterBand(1)->RasterIO(GF_Read, 0, 0, w, h, theirs.data(), w, h, GDT_Float32, 0, 0), CE_None);
  std::size_t differing = 0, near_road = 0;
  for (std::size_t i = 0; i < theirs.size(); ++i) {
    // GDAL applies the coverage's scale (0.01) and returns metres.
    if (std::lround(theirs[i] * 100.0) != ours_cm[i]) ++differing;
    if (ours_cm[i] < 500) ++near_road;
  }
  EXPECT_EQ(differing, 0u);
  EXPECT_GT(near_road, theirs.size() / 50) << "the region must contain roads";

  std::vector<std::uint8_t> ours_rgb;
  reader.read_classes(0, 0, w, h, ours_rgb);
  const auto classes = open_raster(path_, "classes");
  ASSERT_TRUE(classes);
  ASSERT_GE(classes->GetRasterCount(), 3);
  std::vector<std::uint8_t> band(static_cast<std::size_t>(w) * h);
  for (int b = 0; b < 3; ++b) {
    ASSERT_EQ(classes->GetRasterBand(b + 1)->RasterIO(GF_Read, 0, 0, w, h, band.data(), w, h, GDT_Byte, 0, 0), CE_None);
    std::size_t mismatches = 0, labelled = 0;
    for (std::size_t i = 0; i < band.size(); ++i) {
      mismatches += band[i] != ours_rgb[i * 3 + static_cast<std::size_t>(b)];
      labelled += band[i] != 0;
    }
    EXPECT_EQ(mismatches, 0u) << "band " << b + 1;
    EXPECT_GT(labelled, 0u) << "band " << b + 1;
  }
}

TEST_F(GdalInterop, RoadsLayerOpensWithItsGeometry) {
  CacheReader reader(path_);
  const auto roads = reader.roads();
  Dataset ds(GDALDataset::Open(path_.c_str(), GDAL_OF_VECTOR | GDAL_OF_READONLY));
  ASSERT_TRUE(ds);
  OGRLayer* layer = ds->GetLayerByName("roads");
  ASSERT_NE(layer, nullptr);
  EXPECT_EQ(layer->GetFeatureCount(), static_cast<GIntBig>(roads.size()));
  EXPECT_EQ(wkbFlatten(layer->GetGeomType()), wkbLineString);
  OGRFeature* feature = layer->GetNextFeature();
  ASSERT_NE(feature, nullptr);
  const auto* line = feature->GetGeometryRef()->toLineString();
  ASSERT_EQ(line->getNumPoints(), static_cast<int>(roads[0].points.size()));
  EXPECT_DOUBLE_EQ(line->getX(1), roads[0].points[1].x_m);
  EXPECT_DOUBLE_EQ(line->getY(1), roads[0].points[1].y_m);
  EXPECT_EQ(feature->GetFieldAsInteger64("osm_id"), roads[0].osm_id);
  EXPECT_STREQ(feature->GetFieldAsString("highway"), roads[0].highway.c_str());
  OGRFeature::DestroyFeature(feature);
}

}  // namespace
}  // namespace seqloc::raster
