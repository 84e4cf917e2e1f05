// Reading OSM files with libosmium: synthetic files with known content, real extracts, and
// broken input that must fail with a clear error naming the file.

#include <algorithm>
#include <fstream>

#include <gtest/gtest.h>

#include "seqloc/osm/reader.hpp"
#include "seqloc/osm/synthetic.hpp"
#include "support/test_support.hpp"

namespace seqloc::osm {
namespace {

SyntheticMap small_map() {
  SyntheticMap map(47.5, 10.5);
  map.way({{-50, 0}, {50, 0}}, {{"highway", "track"}});
  map.way({{0, 10}, {10, 10}, {10, 20}, {0, 20}}, {{"building", "yes"}}, true);
  map.multipolygon({{{-100, -100}, {100, -100}, {100, 100}, {-100, 100}}},
                   {{{-20, -20}, {20, -20}, {20, 20}, {-20, 20}}}, {{"landuse", "forest"}});
  map.node({5, 5}, {{"natural", "tree"}});
  map.node({6, 6});  // untagged
  return map;
}

TEST(Reader, ClassifiesASyntheticFileInEveryFormat) {
  test::ScratchDir dir;
  for (const char* name : {"map.osm.pbf", "map.osm", "map.osm.gz", "map.osm.bz2"}) {
    const auto path = dir / name;
    small_map().write(path, 10);
    const auto features = read_osm(path);
    SCOPED_TRACE(name);
    ASSERT_EQ(features.lines.size(), 1u);
    EXPECT_EQ(group_name(features.lines[0].group), "road");
    EXPECT_EQ(features.lines[0].highway, "track");
    ASSERT_EQ(features.areas.size(), 2u);
    const auto forest = std::find_if(features.areas.begin(), features.areas.end(),
                                     [](const AreaFeature& a) { return group_name(a.group) == "forest"; });
    ASSERT_NE(forest, features.areas.end());
    EXPECT_TRUE(forest->from_relation);
    EXPECT_EQ(forest->rings.size(), 2u) << "outer and inner ring assembled by libosmium";
    ASSERT_EQ(features.points.size(), 1u);
    EXPECT_EQ(group_name(features.points[0].group), "tree");
    ASSERT_TRUE(features.header_box.has_value());
    EXPECT_TRUE(features.data_box.valid());
  }
}

TEST(Reader, KeepBoxDropsFeaturesFarAway) {
  test::ScratchDir dir;
  SyntheticMap map(47.5, 10.5);
  map.way({{0, 0}, {10, 0}}, {{"highway", "track"}});
  map.way({{5000, 0}, {5010, 0}}, {{"highway", "track"}});
  map.write(dir / "m.osm.pbf");
  const auto near = map.to_geo({0, 0});
  ReadOptions options;
  options.keep_box = GeoBox{near.lon_deg - 0.001, near.lat_deg - 0.001, near.lon_deg + 0.001, near.lat_deg + 0.001};
  EXPECT_EQ(read_osm(dir / "m.osm.pbf", options).lines.size(), 1u);
  EXPECT_EQ(read_osm(dir / "m.osm.pbf").lines.size(), 2u);
}

TEST(Reader, ReadsTheRealNorthBayreuthExtract) {
  const auto path = test::osm_extract("north-bayreuth.osm.pbf");
  const auto features = read_osm(path);
  ASSERT_TRUE(features.header_box.has_value());
  EXPECT_NEAR(features.header_box->min_lon, 11.4807, 1e-3);
  EXPECT_NEAR(features.header_box->max_lat, 50.0470, 1e-3);
  const auto roads = std::count_if(features.lines.begin(), features.lines.end(),
                                   [](const LineFeature& l) { return l.group == kRoad; });
  EXPECT_GT(roads, 500);  // SOURCES.md: 7,801 ways, 28 highway ways per km2 over ~74 km2
  const auto buildings = std::count_if(features.areas.begin(), features.areas.end(),
                                       [](const AreaFeature& a) { return a.group == kBuildingArea; });
  EXPECT_GT(buildings, 1000);
}

void expect_input_error(const std::filesystem::path& path, const std::string& fragment) {
  try {
    (void)read_osm(path);
    FAIL() << "no error for " << path;
  } catch (const OsmInputError& e) {
    const std::string message = e.what();
    EXPECT_NE(message.find(path.string()), std::string::npos) << message;
    EXPECT_NE(message.find(fragment), std::string::npos) << message;
  }
}

TEST(Reader, BadInputGivesOneClearError) {
  test::ScratchDir dir;
  expect_input_error(dir / "missing.osm.pbf", "no such file");
  std::ofstream(dir / "empty.osm.pbf").close();
  expect_input_error(dir / "empty.osm.pbf", "empty file");
  std::ofstream(dir / "garbage.osm.pbf") << "this is not a protobuf file at all, just some text";
  expect_input_error(dir / "garbage.osm.pbf", "cannot read OSM data");
  std::ofstream(dir / "bad.osm") << "<osm version='0.6'><node id='1' lat='1' lon='1'>";
  expect_input_error(dir / "bad.osm", "cannot read OSM data");
  expect_input_error(dir.path(), "is a directory");
}

TEST(Reader, TruncatedRealPbfFails) {
  const auto path = test::osm_extract("monaco.osm.pbf");
  test::ScratchDir dir;
  const std::string bytes = test::read_file(path);
  for (const double fraction : {0.5, 0.9, 0.999}) {
    const auto cut = dir / ("cut" + std::to_string(static_cast<int>(fraction * 1000)) + ".osm.pbf");
    std::ofstream(cut, std::ios::binary)
        .write(bytes.data(), static_cast<std::streamsize>(static_cast<double>(bytes.size()) * fraction));
    expect_input_error(cut, "cannot read OSM data");
  }
}

TEST(Reader, ReadsBuffersInMemoryAsItReadsFiles) {
  test::ScratchDir dir;
  for (const auto& [name, format] : {std::pair{"map.osm.pbf", "pbf"}, std::pair{"map.osm", "xml"}}) {
    small_map().write(dir / name, 10);
    const std::string bytes = test::read_file(dir / name);
    const auto from_file = read_osm(dir / name);
    const auto from_buffer = read_osm_buffer(bytes, format, "buffer");
    SCOPED_TRACE(name);
    EXPECT_EQ(from_buffer.lines.size(), from_file.lines.size());
    EXPECT_EQ(from_buffer.areas.size(), from_file.areas.size());
    EXPECT_EQ(from_buffer.points.size(), from_file.points.size());
    ASSERT_EQ(from_buffer.lines.size(), 1u);
    EXPECT_EQ(from_buffer.lines[0].points.size(), from_file.lines[0].points.size());
  }
  EXPECT_THROW((void)read_osm_buffer(std::string_view(), "pbf", "empty"), OsmInputError);
  EXPECT_THROW((void)read_osm_buffer(std::string_view("x"), "shp", "odd"), OsmInputError);
}

// A PBF is a sequence of (4-byte big-endian length, BlobHeader, Blob). Sizes declared in those
// headers are checked against libosmium's limits (64 KiB header, 32 MiB blob) before anything
// of that size is allocated: a hostile or corrupt file cannot ask for gigabytes.
std::string varint(std::uint64_t v) {
  std::string out;
  while (v >= 0x80) {
    out.push_back(static_cast<char>((v & 0x7f) | 0x80));
    v >>= 7;
  }
  out.push_back(static_cast<char>(v));
  return out;
}

std::string be32(std::uint32_t v) {
  return {static_cast<char>(v >> 24), static_cast<char>(v >> 16), static_cast<char>(v >> 8), static_cast<char>(v)};
}

std::string blob_header(const std::string& type, std::uint64_t datasize) {
  std::string h = "\x0a" + varint(type.size()) + type + "\x18" + varint(datasize);
  return be32(static_cast<std::uint32_t>(h.size())) + h;
}

TEST(Reader, AbsurdPbfSizesAreRefusedBeforeAllocation) {
  test::ScratchDir dir;
  auto expect_refused = [&](const std::string& name, const std::string& bytes, const std::string& fragment) {
    std::ofstream(dir / name, std::ios::binary) << bytes;
    expect_input_error(dir / name, fragment);
  };
  // A BlobHeader claiming 2 GiB.
  expect_refused("header.osm.pbf", be32(0x7fffffffu) + std::string(64, 'x'), "max_blob_header_size");
  // A Blob claiming 2 GiB (the header's datasize).
  expect_refused("datasize.osm.pbf", blob_header("OSMHeader", 0x7fffffffu) + std::string(64, 'x'), "invalid blob size");
  // A Blob whose declared uncompressed size is 2 GiB.
  const std::string blob = "\x10" + varint(0x7fffffffu) + "\x1a" + varint(4) + "abcd";
  expect_refused("rawsize.osm.pbf", blob_header("OSMHeader", blob.size()) + blob, "size");
}

TEST(Reader, HashesFiles) {
  test::ScratchDir dir;
  std::ofstream(dir / "abc.txt") << "abc";
  // FIPS 180-2 test vector.
  EXPECT_EQ(file_sha256(dir / "abc.txt"), "ba7816bf8f01cfea414140de5dae2223b00361a396177a9cb410ff61f20015ad");
}

}  // namespace
}  // namespace seqloc::osm
