// The road-prior service, endpoint by endpoint, on the Monaco extract: tiles against the cache's
// own tiles, crops against the cell-centre formula of conventions.md, errors and limits, ETags, and
// the HTTP layer's limits and deadlines.

#include <gtest/gtest.h>
#include <nlohmann/json.hpp>

#include <arpa/inet.h>
#include <netinet/in.h>
#include <sys/socket.h>
#include <sys/time.h>
#include <unistd.h>

#include <cerrno>
#include <chrono>
#include <cmath>
#include <cstring>
#include <future>
#include <random>
#include <thread>

#include <cpl_vsi.h>
#include <gdal.h>
#include <httplib.h>

#include "seqloc/ingest/preprocess.hpp"
#include "seqloc/serve/geotiff.hpp"
#include "seqloc/serve/server.hpp"
#include "seqloc/serve/service.hpp"
#include "serve/monaco_cache.hpp"
#include "support/test_support.hpp"

namespace seqloc::serve {
namespace {

using test_data::monaco_cache;

// An HttpServer on a free port, listening in its own thread; stopped and joined on every way out
// of a test, an ASSERT's early return included (a joinable std::thread would abort the binary).
class ListeningServer {
 public:
  ListeningServer(Service& service, const ServerOptions& options) : server_(service, on_a_free_port(options)) {
    server_.bind();
    listener_ = std::thread([this] { server_.listen(); });
  }
  ~ListeningServer() {
    server_.stop();
    listener_.join();
  }
  ListeningServer(const ListeningServer&) = delete;
  ListeningServer& operator=(const ListeningServer&) = delete;
  HttpServer& server() { return server_; }

 private:
  static ServerOptions on_a_free_port(const ServerOptions& options) {
    ServerOptions free = options;
    free.port = 0;
    return free;
  }
  HttpServer server_;
  std::thread listener_;
};

class ServiceTest : public ::testing::Test {
 protected:
  void SetUp() override {
    service_ = std::make_unique<Service>(std::vector<std::filesystem::path>{monaco_cache()}, ServiceOptions{});
    cache_ = std::make_unique<raster::CacheReader>(monaco_cache());
  }
  Response get(const std::string& path, std::multimap<std::string, std::string> query = {}) {
    Request r;
    r.path = path;
    r.query = std::move(query);
    return service_->handle(r);
  }
  static std::string header(const Response& r, const std::string& name) {
    for (const auto& [k, v] : r.headers) {
      if (k == name) return v;
    }
    return {};
  }
  /// The array part of an .npy body whose header the test checks: descr and shape.
  template <class T>
  static std::vector<T> npy_values(const std::string& body, const std::string& descr, const std::string& shape) {
    const std::size_t header_len = static_cast<unsigned char>(body[8]) | (static_cast<unsigned char>(body[9]) << 8);
    const std::string header = body.substr(10, header_len);
    EXPECT_NE(header.find("'descr': '" + descr + "'"), std::string::npos) << header;
    EXPECT_NE(header.find("'shape': " + shape), std::string::npos) << header;
    EXPECT_EQ((10 + header_len) % 64, 0u);
    std::vector<T> values((body.size() - 10 - header_len) / sizeof(T));
    std::memcpy(values.data(), body.data() + 10 + header_len, values.size() * sizeof(T));
    return values;
  }
  std::unique_ptr<Service> service_;
  std::unique_ptr<raster::CacheReader> cache_;
};

TEST_F(ServiceTest, HealthAndCatalogDescribeTheRegion) {
  const Response health = get("/health");
  EXPECT_EQ(health.status, 200);
  EXPECT_NE(health.text().find("\"ok\""), std::string::npos);
  const Response catalog = get("/catalog");
  ASSERT_EQ(catalog.status, 200);
  EXPECT_NE(catalog.text().find("\"id\": \"monaco\""), std::string::npos);
  EXPECT_NE(catalog.text().find("\"columns\": " + std::to_string(cache_->grid().tiles_wide())), std::string::npos);
  const Response tj = get("/regions/monaco/tilejson.json");
  ASSERT_EQ(tj.status, 200);
  EXPECT_NE(tj.text().find("\"tilejson\": \"3.0.0\""), std::string::npos);
  const Response wmts = get("/regions/monaco/wmts.xml");
  ASSERT_EQ(wmts.status, 200);
  EXPECT_NE(wmts.text().find("<MatrixWidth>" + std::to_string(cache_->grid().tiles_wide()) + "</MatrixWidth>"),
            std::string::npos);
}

TEST_F(ServiceTest, PngTilesAreTheStoredTiles) {
  for (auto [col, row] : {std::pair{0, 0}, std::pair{6, 7}, std::pair{13, 13}}) {
    for (auto [layer, name] :
         {std::pair{raster::Layer::classes, "classes"}, std::pair{raster::Layer::road_distance, "road_distance"}}) {
      const Response r =
          get("/regions/monaco/" + std::string(name) + "/" + std::to_string(col) + "/" + std::to_string(row) + ".png");
      ASSERT_EQ(r.status, 200) << r.text();
      EXPECT_EQ(r.content_type, "image/png");
      const auto blob = cache_->tile_blob(layer, col, row);
      EXPECT_EQ(r.text(), std::string(blob.begin(), blob.end()));
    }
  }
}

TEST_F(ServiceTest, NpyTilesHoldMetresAndTheRoadPrior) {
  const int col = 6, row = 7;
  const auto cm = cache_->distance_tile(col, row);
  const auto distance = npy_values<float>(get("/regions/monaco/road_distance/6/7.npy").text(), "<f4", "(512, 512)");
  const auto prior = npy_values<float>(get("/regions/monaco/road_prior/6/7.npy").text(), "<f4", "(512, 512)");
  ASSERT_EQ(distance.size(), cm->size());
  ASSERT_EQ(prior.size(), cm->size());
  int near_road = 0;
  for (std::size_t i = 0; i < cm->size(); ++i) {
    const double d = (*cm)[i] / 100.0;
    ASSERT_NEAR(distance[i], d, 1e-5);
    // g = exp(-d^2 / (2 sigma^2)) with the default sigma of 3 m, computed here independently.
    ASSERT_NEAR(prior[i], std::exp(-d * d / 18.0), 1e-6);
    near_road += d < 3;
  }
  EXPECT_GT(near_road, 1000);  // the tile has roads, so the prior is not trivially flat
  const auto rgb = cache_->classes_tile(col, row);
  const auto classes = npy_values<std::uint8_t>(get("/regions/monaco/classes/6/7.npy").text(), "|u1", "(512, 512, 3)");
  EXPECT_EQ(classes, *rgb);
}

TEST_F(ServiceTest, GeoTiffTilesCarryTheTilesGeoreference) {
  const Response r = get("/regions/monaco/road_distance/3/9.tif");
  ASSERT_EQ(r.status, 200) << r.text();
  GDALAllRegister();
  const std::string name = "/vsimem/test_tile.tif";
  VSIFCloseL(VSIFileFromMemBuffer(name.c_str(), reinterpret_cast<GByte*>(const_cast<char*>(r.text().data())),
                                  r.text().size(), FALSE));
  GDALDatasetH ds = GDALOpen(name.c_str(), GA_ReadOnly);
  ASSERT_NE(ds, nullptr);
  double gt[6];
  ASSERT_EQ(GDALGetGeoTransform(ds, gt), CE_None);
  const auto& g = cache_->grid();
  EXPECT_DOUBLE_EQ(gt[0], g.min_x() + 3 * 256.0);
  EXPECT_DOUBLE_EQ(gt[3], g.max_y() - 9 * 256.0);
  EXPECT_DOUBLE_EQ(gt[1], 0.5);
  EXPECT_DOUBLE_EQ(gt[5], -0.5);
  std::vector<float> values(512 * 512);
  ASSERT_EQ(GDALRasterIO(GDALGetRasterBand(ds, 1), GF_Read, 0, 0, 512, 512, values.data(), 512, 512, GDT_Float32, 0, 0),
            CE_None);
  const auto cm = cache_->distance_tile(3, 9);
  for (std::size_t i = 0; i < values.size(); i += 97) ASSERT_NEAR(values[i], (*cm)[i] / 100.0, 1e-5);
  GDALClose(ds);
  VSIUnlink(name.c_str());
}

// conventions.md section 4: cell (v, u) of a crop lies at ((u - (W-1)/2) * 0.5, -(v - (H-1)/2) * 0.5)
// from its centre (crop_x, crop_y). Every crop cell found that way must be the cache's cell there.
TEST_F(ServiceTest, CropCellsSitWhereTheConventionPutsThem) {
  const auto& g = cache_->grid();
  const auto projection = cache_->metadata().projection();
  std::mt19937 rng(7);
  std::uniform_real_distribution<double> ux(g.min_x() + 300, g.max_x() - 300), uy(g.min_y() + 300, g.max_y() - 300);
  for (int trial = 0; trial < 8; ++trial) {
    const double size_m = trial % 2 ? 32.5 : 40.0;  // 65 cells (odd), 80 cells (even)
    const osm::GeoPoint where = projection.reverse({ux(rng), uy(rng)});
    const Response r = get("/regions/monaco/crop", {{"lat", std::to_string(where.lat_deg)},
                                                    {"lon", std::to_string(where.lon_deg)},
                                                    {"size_m", std::to_string(size_m)},
                                                    {"layers", "classes,road_distance"}});
    ASSERT_EQ(r.status, 200) << r.text();
    const int n = static_cast<int>(size_m * 2);
    const double cx = std::stod(header(r, "X-Seqloc-Crop-X")), cy = std::stod(header(r, "X-Seqloc-Crop-Y"));
    // The crop's centre is within half a cell of the point, per axis (a cell centre or corner).
    const auto p =
        projection.forward({std::stod(std::to_string(where.lat_deg)), std::stod(std::to_string(where.lon_deg))});
    EXPECT_LE(std::abs(p.x_m - cx), 0.25 + 1e-6);
    EXPECT_LE(std::abs(p.y_m - cy), 0.25 + 1e-6);
    const auto values = npy_values<float>(r.text(), "<f4", "(" + std::to_string(n) + ", " + std::to_string(n) + ", 4)");
    for (int v = 0; v < n; v += 7) {
      for (int u = 0; u < n; u += 5) {
        const double x = cx + (u - (n - 1) / 2.0) * 0.5, y = cy - (v - (n - 1) / 2.0) * 0.5;
        const double ru = g.region_u(x), rv = g.region_v(y);
        ASSERT_NEAR(ru, std::round(ru), 1e-9);
        ASSERT_NEAR(rv, std::round(rv), 1e-9);
        std::vector<std::uint8_t> rgb;
        std::vector<std::uint16_t> cm;
        cache_->read_classes(std::llround(ru), std::llround(rv), 1, 1, rgb);
        cache_->read_road_distance(std::llround(ru), std::llround(rv), 1, 1, cm);
        const std::size_t i = (static_cast<std::size_t>(v) * n + static_cast<std::size_t>(u)) * 4;
        ASSERT_EQ(values[i + 0], rgb[0]);
        ASSERT_EQ(values[i + 1], rgb[1]);
        ASSERT_EQ(values[i + 2], rgb[2]);
        ASSERT_NEAR(values[i + 3], cm[0] / 100.0, 1e-5);
      }
    }
  }
}

TEST_F(ServiceTest, CropSidecarAgreesWithTheHeaders) {
  const std::multimap<std::string, std::string> q{{"lat", "43.7384"}, {"lon", "7.4246"}, {"size_m", "64"}};
  const Response crop = get("/regions/monaco/crop", q);
  const Response sidecar = get("/regions/monaco/crop.json", q);
  ASSERT_EQ(crop.status, 200);
  ASSERT_EQ(sidecar.status, 200);
  EXPECT_EQ(header(crop, "X-Seqloc-Shape"), "128,128,5");
  const double cx = std::stod(header(crop, "X-Seqloc-Crop-X"));
  EXPECT_NE(sidecar.text().find("\"crop_x\": " + std::to_string(static_cast<int>(cx))), std::string::npos)
      << sidecar.text();
  EXPECT_NE(sidecar.text().find("\"road_prior\""), std::string::npos);
}

TEST_F(ServiceTest, PointOnARoadHasNoDistance) {
  const auto roads = cache_->roads();
  ASSERT_FALSE(roads.empty());
  const auto projection = cache_->metadata().projection();
  int checked = 0;
  for (std::size_t i = 0; i < roads.size() && checked < 20; i += roads.size() / 20 + 1) {
    const auto& vertex = roads[i].points[roads[i].points.size() / 2];
    const auto where = projection.reverse({vertex.x_m, vertex.y_m});
    char path[128];
    std::snprintf(path, sizeof path, "/regions/monaco/point/%.9f,%.9f", where.lon_deg, where.lat_deg);
    const Response r = get(path);
    ASSERT_EQ(r.status, 200) << r.text();
    // A vertex's own cell is drawn as a road cell: distance 0, prior 1, and some way there (the
    // ways channel may show another group that takes precedence, e.g. a path crossing).
    EXPECT_NE(r.text().find("\"road_distance_m\": 0.0"), std::string::npos) << r.text();
    EXPECT_NE(r.text().find("\"road_prior\": 1.0"), std::string::npos) << r.text();
    EXPECT_EQ(r.text().find("\"ways\": {\n      \"code\": 0,"), std::string::npos) << r.text();
    ++checked;
  }
  EXPECT_GE(checked, 10);
}

struct BadRequest {
  std::string path;
  std::multimap<std::string, std::string> query;
  int status;
  std::string message;  ///< a part of the error message
};

TEST_F(ServiceTest, BadRequestsGetOneClearError) {
  const std::vector<BadRequest> cases = {
      {"/regions/monaco/classes/14/0.png", {}, 404, "outside"},
      {"/regions/monaco/classes/0/99999.png", {}, 404, "outside"},
      {"/regions/monaco/classes/-1/0.png", {}, 400, "non-negative integers"},
      {"/regions/monaco/classes/1e3/0.png", {}, 400, "non-negative integers"},
      {"/regions/monaco/classes/0/0.jpg", {}, 404, "tile format"},
      {"/regions/monaco/buildings/0/0.png", {}, 404, "no layer"},
      {"/regions/atlantis/classes/0/0.png", {}, 404, "no region"},
      {"/regions/monaco/classes/0/0.npy", {{"style", "color"}}, 400, "PNG style"},
      {"/regions/monaco/crop", {{"lon", "7.42"}}, 400, "lat: missing"},
      {"/regions/monaco/crop", {{"lat", "abc"}, {"lon", "7.42"}}, 400, "not a number"},
      {"/regions/monaco/crop", {{"lat", "nan"}, {"lon", "7.42"}}, 400, "not a number"},
      {"/regions/monaco/crop", {{"lat", "43.7"}, {"lat", "43.8"}, {"lon", "7.42"}}, 400, "more than once"},
      {"/regions/monaco/crop", {{"lat", "43.7384"}, {"lon", "7.4246"}, {"size_m", "100000"}}, 400, "above the limit"},
      {"/regions/monaco/crop", {{"lat", "43.7384"}, {"lon", "7.4246"}, {"size_m", "0"}}, 400, "at least one cell"},
      {"/regions/monaco/crop", {{"lat", "48.0"}, {"lon", "11.0"}}, 404, "outside the region"},
      {"/regions/monaco/crop", {{"lat", "95"}, {"lon", "7.4"}}, 400, "not a WGS84"},
      {"/regions/monaco/crop",
       {{"lat", "43.7384"}, {"lon", "7.4246"}, {"layers", "classes,roads"}},
       400,
       "unknown layer"},
      {"/regions/monaco/crop", {{"lat", "43.7384"}, {"lon", "7.4246"}, {"format", "png"}}, 400, "one layer"},
      {"/regions/monaco/crop", {{"lat", "43.7384"}, {"lon", "7.4246"}, {"format", "jpeg"}}, 400, "format"},
      {"/regions/monaco/point/7.4246", {}, 400, "LON,LAT"},
      {"/regions/monaco/point/11.0,48.0", {}, 404, "outside region"},
      {"/static/../../etc/passwd", {}, 404, "no such"},
      {"/regions/../etc/passwd", {}, 404, "no such"},
      {"/", {}, 404, "no viewer page"},
      {"/nothing", {}, 404, "no such resource"},
  };
  for (const auto& c : cases) {
    const Response r = get(c.path, c.query);
    EXPECT_EQ(r.status, c.status) << c.path << " " << r.text();
    EXPECT_EQ(r.content_type, "application/json") << c.path;
    EXPECT_NE(r.text().find(c.message), std::string::npos) << c.path << ": " << r.text();
  }
  Request post;
  post.method = "POST";
  post.path = "/health";
  EXPECT_EQ(service_->handle(post).status, 405);
}

TEST(HttpStatus, FromTheErrorOnce) {
  using raster::CropError;
  EXPECT_EQ(http_status(RequestError(RequestError::Kind::not_found, "x")), 404);
  EXPECT_EQ(http_status(RequestError(RequestError::Kind::bad_request, "x")), 400);
  EXPECT_EQ(http_status(CropError(CropError::Kind::outside, "x")), 404) << "a point outside the region";
  EXPECT_EQ(http_status(CropError(CropError::Kind::bad_argument, "x")), 400);
  EXPECT_EQ(http_status(raster::CacheRangeError("x")), 404);
  EXPECT_EQ(http_status(UsageError("x")), 400);
  EXPECT_EQ(http_status(NotFoundError("x")), 404) << "by the category alone, whatever the class";
  EXPECT_EQ(http_status(DataError("x")), 500);
  EXPECT_EQ(http_status(raster::CacheFormatError("x")), 500) << "a damaged cache is the server's fault";
  EXPECT_EQ(http_status(ExportError("x")), 500);
  EXPECT_EQ(http_status(std::runtime_error("x")), 500);
}

TEST(ParseRequest, DecodesTheTargetLikeABrowserEncodesIt) {
  const Request r =
      parse_request("GET", "/regions/mon%61co/crop?lat=43.7&lon=%2D7.4&layers=classes%2Croad_prior&q=a+b&&=x&flag");
  EXPECT_EQ(r.method, "GET");
  EXPECT_EQ(r.path, "/regions/monaco/crop");
  const std::multimap<std::string, std::string> expected{
      {"lat", "43.7"}, {"lon", "-7.4"}, {"layers", "classes,road_prior"}, {"q", "a b"}, {"flag", ""}};
  EXPECT_EQ(r.query, expected);
  EXPECT_EQ(parse_request("GET", "/a+b").path, "/a+b") << "'+' is a space only in the query";
  EXPECT_TRUE(parse_request("GET", "/health?").query.empty());
  EXPECT_EQ(parse_request("GET", "/x?a=1#frag").query.size(), 1u);
}

TEST(ParseRequest, RefusesMalformedTargets) {
  const std::vector<std::pair<std::string, std::string>> cases = {
      {"", "starting with '/'"},
      {"regions", "starting with '/'"},
      {"http://example.com/health", "starting with '/'"},
      {"/bad%2", "malformed"},
      {"/bad%zz", "malformed"},
      {"/x?a=%", "malformed"},
      {"/nul%00byte", "control character"},
      {"/x?a=line%0Abreak", "control character"},
      {"/" + std::string(kMaxTargetBytes, 'a'), "at most"},
  };
  for (const auto& [target, fragment] : cases) {
    try {
      (void)parse_request("GET", target);
      ADD_FAILURE() << "accepted: " << target.substr(0, 40);
    } catch (const RequestError& e) {
      EXPECT_EQ(e.kind(), RequestError::Kind::bad_request);
      EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << target.substr(0, 40) << ": " << e.what();
    }
  }
}

TEST_F(ServiceTest, ErrorsEchoingBytesThatAreNotUtf8AreValidJson) {
  // Found by fuzz/request: the message quoted the parameter, and the JSON dump threw on it.
  const Response r = get("/regions/monaco/crop", {{"lat", "43.7\xfe"}, {"lon", "7.42"}});
  EXPECT_EQ(r.status, 400);
  const auto body = nlohmann::json::parse(r.text());
  EXPECT_NE(body["error"]["message"].get<std::string>().find("\xef\xbf\xbd"), std::string::npos) << r.text();
  const Response missing = get("/regions/\xc3\x28/classes/0/0.png");
  EXPECT_EQ(missing.status, 404);
  EXPECT_TRUE(nlohmann::json::accept(missing.text())) << missing.text();
}

TEST_F(ServiceTest, TilesHaveETagsAndComeFromMemoryTheSecondTime) {
  const Response first = get("/regions/monaco/road_prior/4/4.png");
  ASSERT_EQ(first.status, 200);
  const std::string etag = header(first, "ETag");
  EXPECT_FALSE(etag.empty());
  EXPECT_NE(header(first, "Cache-Control").find("max-age"), std::string::npos);
  const auto hits = service_->stats().cache_hits;
  const Response second = get("/regions/monaco/road_prior/4/4.png");
  EXPECT_EQ(service_->stats().cache_hits, hits + 1);
  EXPECT_EQ(second.body, first.body);  // the same buffer
  Request conditional;
  conditional.path = "/regions/monaco/road_prior/4/4.png";
  conditional.if_none_match = etag;
  const Response not_modified = service_->handle(conditional);
  EXPECT_EQ(not_modified.status, 304);
  EXPECT_TRUE(not_modified.text().empty());
  conditional.if_none_match = "\"something-else\"";
  EXPECT_EQ(service_->handle(conditional).status, 200);
  EXPECT_NE(header(get("/regions/monaco/road_prior/4/5.png"), "ETag"), etag);
}

// A raw client socket, connected from a chosen loopback address (the server counts connections
// per client address), with a receive timeout so that a test never hangs on it.
class RawClient {
 public:
  explicit RawClient(int port, const char* from = "127.0.0.1") : fd_(::socket(AF_INET, SOCK_STREAM, 0)) {
    timeval limit{20, 0};
    ::setsockopt(fd_, SOL_SOCKET, SO_RCVTIMEO, &limit, sizeof limit);
    sockaddr_in source{};
    source.sin_family = AF_INET;
    ::inet_pton(AF_INET, from, &source.sin_addr);
    connected_ = ::bind(fd_, reinterpret_cast<sockaddr*>(&source), sizeof source) == 0;
    sockaddr_in server{};
    server.sin_family = AF_INET;
    server.sin_port = htons(static_cast<std::uint16_t>(port));
    server.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    connected_ = connected_ && ::connect(fd_, reinterpret_cast<sockaddr*>(&server), sizeof server) == 0;
  }
  ~RawClient() { ::close(fd_); }
  RawClient(const RawClient&) = delete;
  RawClient& operator=(const RawClient&) = delete;

  [[nodiscard]] bool connected() const { return connected_; }
  bool send(const std::string& bytes) {
    return ::send(fd_, bytes.data(), bytes.size(), MSG_NOSIGNAL) == static_cast<ssize_t>(bytes.size());
  }
  /// One response: its status (0 when the connection closed or timed out first) and body.
  std::pair<int, std::string> response() {
    while (pending_.find("\r\n\r\n") == std::string::npos) {
      if (!receive()) return {0, {}};
    }
    const std::size_t head_end = pending_.find("\r\n\r\n") + 4;
    const std::string head = pending_.substr(0, head_end);
    std::size_t length = 0;
    if (const auto at = head.find("Content-Length: "); at != std::string::npos)
      length = std::stoul(head.substr(at + 16));
    while (pending_.size() < head_end + length) {
      if (!receive()) return {0, {}};
    }
    const int status = std::stoi(head.substr(9, 3));
    std::string body = pending_.substr(head_end, length);
    pending_.erase(0, head_end + length);
    return {status, body};
  }
  /// Whether the server closed the connection (end of stream or reset) before the receive timeout.
  bool closed_by_server() {
    char byte = 0;
    const auto n = ::recv(fd_, &byte, 1, 0);
    return n == 0 || (n < 0 && errno != EAGAIN && errno != EWOULDBLOCK);
  }

 private:
  bool receive() {
    char chunk[4096];
    const auto n = ::recv(fd_, chunk, sizeof chunk, 0);
    if (n <= 0) return false;
    pending_.append(chunk, static_cast<std::size_t>(n));
    return true;
  }
  int fd_;
  bool connected_ = false;
  std::string pending_;
};

const std::string kGetHealth = "GET /health HTTP/1.1\r\nHost: test\r\n\r\n";

// Polls (no fixed sleeps: the sanitizer build on a loaded machine is slow).
template <class Condition>
bool eventually(Condition condition) {
  for (int i = 0; i < 2000; ++i) {
    if (condition()) return true;
    std::this_thread::sleep_for(std::chrono::milliseconds(5));
  }
  return condition();
}

TEST_F(ServiceTest, HttpServerAnswersAndTurnsAwayConnectionsPastItsLimits) {
  ServerOptions options;
  options.threads = 1;
  options.max_connections = 3;
  options.max_per_client = 2;
  ListeningServer running(*service_, options);
  HttpServer& server = running.server();
  {
    httplib::Client client("127.0.0.1", server.port());
    client.set_keep_alive(true);
    const auto health = client.Get("/health");
    ASSERT_TRUE(health);
    EXPECT_EQ(health->status, 200);
    const auto tile = client.Get("/regions/monaco/classes/2/2.png");
    ASSERT_TRUE(tile);
    EXPECT_EQ(tile->status, 200);
    EXPECT_EQ(tile->get_header_value("Content-Type"), "image/png");
    EXPECT_EQ(tile->body, get("/regions/monaco/classes/2/2.png").text());
    // HEAD: the GET's headers, its length, no body.
    const auto head = client.Head("/regions/monaco/classes/2/2.png");
    ASSERT_TRUE(head);
    EXPECT_EQ(head->status, 200);
    EXPECT_EQ(head->get_header_value("Content-Length"), std::to_string(tile->body.size()));
    EXPECT_TRUE(head->body.empty());
  }
  ASSERT_TRUE(eventually([&] { return server.open_connections() == 0; }));
  // Two connections from 127.0.0.1 that send nothing: the client's limit. They hold no thread.
  RawClient a(server.port()), b(server.port());
  ASSERT_TRUE(a.connected() && b.connected());
  ASSERT_TRUE(eventually([&] { return server.open_connections() == 2; }));
  // A third from the same address is turned away at once with a 503 ...
  RawClient c(server.port());
  ASSERT_TRUE(c.connected());
  EXPECT_EQ(c.response().first, 503);
  EXPECT_EQ(server.rejected(), 1u);
  // ... while another address is served, by the only thread, although two clients are idle.
  RawClient d(server.port(), "127.0.0.2");
  ASSERT_TRUE(d.connected() && d.send(kGetHealth));
  EXPECT_EQ(d.response().first, 200);
  // d stays open: 3 connections, the total limit, so a fourth address is turned away too.
  RawClient e(server.port(), "127.0.0.3");
  ASSERT_TRUE(e.connected());
  EXPECT_EQ(e.response().first, 503);
  EXPECT_EQ(server.rejected(), 2u);
  // The idle ones still get their answer when they do ask.
  ASSERT_TRUE(a.send(kGetHealth));
  EXPECT_EQ(a.response().first, 200);
}

TEST_F(ServiceTest, HttpServerClosesConnectionsThatMissTheirDeadlines) {
  ServerOptions options;
  options.threads = 1;
  options.header_timeout_s = 0.5;
  options.keep_alive_s = 1.0;
  ListeningServer running(*service_, options);
  HttpServer& server = running.server();
  // Half a head and then nothing (a slowloris): closed at the head deadline ...
  RawClient slow(server.port());
  ASSERT_TRUE(slow.connected() && slow.send("GET /health HTTP/1.1\r\nHost: te"));
  const auto start = std::chrono::steady_clock::now();
  // ... and meanwhile the only thread answers someone else.
  RawClient other(server.port(), "127.0.0.2");
  ASSERT_TRUE(other.connected() && other.send(kGetHealth));
  EXPECT_EQ(other.response().first, 200);
  EXPECT_TRUE(slow.closed_by_server());
  EXPECT_GE(std::chrono::steady_clock::now() - start, std::chrono::milliseconds(400));
  // A connection that sends a head one byte at a time, each byte well within the idle time,
  // is still closed at the head deadline: it runs from the first byte, not from the last.
  RawClient dribble(server.port());
  ASSERT_TRUE(dribble.connected());
  const auto dribble_start = std::chrono::steady_clock::now();
  bool cut = false;
  for (char ch :
       std::string("GET /health HTTP/1.1\r\nX-Slow: aaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaaa\r\n\r\n")) {
    if (!dribble.send(std::string(1, ch))) {
      cut = true;
      break;
    }
    std::this_thread::sleep_for(std::chrono::milliseconds(50));
  }
  // ~70 bytes x 50 ms = 3.5 s of dribbling against a 0.5 s head deadline.
  EXPECT_TRUE(cut || dribble.closed_by_server());
  EXPECT_LT(std::chrono::steady_clock::now() - dribble_start, std::chrono::seconds(3));
  // A kept-alive connection idle past --keep-alive after its answer is closed.
  RawClient idle(server.port());
  ASSERT_TRUE(idle.connected() && idle.send(kGetHealth));
  EXPECT_EQ(idle.response().first, 200);
  EXPECT_TRUE(idle.closed_by_server());
  EXPECT_GE(server.timed_out(), 3u);
}

TEST_F(ServiceTest, HttpServerRefusesOversizedHeadsAndBodies) {
  ServerOptions options;
  options.threads = 1;
  ListeningServer running(*service_, options);
  const int port = running.server().port();
  // A head over max_header_bytes: a 431, then the connection is closed.
  RawClient big_head(port);
  ASSERT_TRUE(big_head.connected());
  ASSERT_TRUE(
      big_head.send("GET /health HTTP/1.1\r\nX-Big: " + std::string(options.max_header_bytes, 'a') + "\r\n\r\n"));
  EXPECT_EQ(big_head.response().first, 431);
  EXPECT_TRUE(big_head.closed_by_server());
  // A declared body over max_body_bytes: a 413 before a byte of it is read.
  RawClient big_body(port);
  ASSERT_TRUE(big_body.connected());
  ASSERT_TRUE(big_body.send("POST /health HTTP/1.1\r\nHost: test\r\nContent-Length: 1000000000\r\n\r\n"));
  const auto refused = big_body.response();
  EXPECT_EQ(refused.first, 413);
  EXPECT_NE(refused.second.find("body"), std::string::npos) << refused.second;
  // A small body is read, ignored, and the method still decides (405 for a POST).
  RawClient small_body(port);
  ASSERT_TRUE(small_body.connected());
  ASSERT_TRUE(small_body.send("POST /health HTTP/1.1\r\nHost: test\r\nContent-Length: 5\r\n\r\nhello" + kGetHealth));
  EXPECT_EQ(small_body.response().first, 405);
  EXPECT_EQ(small_body.response().first, 200);  // the pipelined request after it
  // Not HTTP at all: a 400 naming the problem.
  RawClient garbage(port);
  ASSERT_TRUE(garbage.connected() && garbage.send("\x01\x02\x03 nonsense\r\n\r\n"));
  EXPECT_EQ(garbage.response().first, 400);
}

TEST_F(ServiceTest, HttpServerDecodesTheRawTargetItself) {
  ServerOptions options;
  options.threads = 2;
  ListeningServer running(*service_, options);
  httplib::Client client("127.0.0.1", running.server().port());
  const auto escaped = client.Get("/regions/mon%61co/classes/2/2.png");  // decoded by parse_request
  ASSERT_TRUE(escaped);
  EXPECT_EQ(escaped->status, 200) << escaped->body;
  const auto malformed = client.Get("/regions/monaco/classes/2/2.png?x=%zz");
  ASSERT_TRUE(malformed);
  EXPECT_EQ(malformed->status, 400);
  EXPECT_NE(malformed->body.find("malformed"), std::string::npos) << malformed->body;
}

TEST_F(ServiceTest, AStopBeforeListenStartsStopsTheListen) {
  // seqloc serve's SIGTERM can arrive between bind() and listen(): the listen that follows must
  // not serve on.
  ServerOptions options;
  options.port = 0;
  HttpServer server(*service_, options);
  server.bind();
  server.stop();
  auto listening = std::async(std::launch::async, [&] { server.listen(); });
  const bool returned = listening.wait_for(std::chrono::seconds(10)) == std::future_status::ready;
  EXPECT_TRUE(returned) << "listen() served on after stop()";
  if (!returned) server.stop();  // now running: let the test end
}

TEST_F(ServiceTest, ServerOptionsAreValidated) {
  const auto message = [](const ServerOptions& options) {
    try {
      options.validate();
    } catch (const ServiceError& e) {
      return std::string(e.what());
    }
    return std::string();
  };
  EXPECT_EQ(message(ServerOptions{}), "");
  ServerOptions options;
  options.threads = 0;
  EXPECT_NE(message(options).find("--threads 0"), std::string::npos) << message(options);
  options = {};
  options.port = 70000;
  EXPECT_NE(message(options).find("--port 70000"), std::string::npos) << message(options);
  options = {};
  options.header_timeout_s = 0;
  EXPECT_NE(message(options).find("--header-timeout"), std::string::npos) << message(options);
  options = {};
  options.max_connections = 100;
  options.max_per_client = 101;
  EXPECT_NE(message(options).find("--max-per-client 101"), std::string::npos) << message(options);
}

// Two builds of the sample region that differ in every road-distance tile (another clamp).
struct TwoBuilds {
  test::ScratchDir dir;
  std::filesystem::path a = dir / "a.gpkg", b = dir / "b.gpkg";
  TwoBuilds() {
    for (const auto& [out, clamp] : {std::pair{a, 40.0}, std::pair{b, 90.0}}) {
      ingest::PreprocessOptions options;
      options.input = std::filesystem::path(SEQLOC_SOURCE_DIR) / "samples" / "rural-valley.osm.pbf";
      options.output = out;
      options.max_distance_m = clamp;
      options.threads = 2;
      (void)ingest::preprocess_region(options);
    }
  }
  static std::string blob(const std::filesystem::path& cache, std::int64_t col, std::int64_t row) {
    const auto bytes = raster::CacheReader(cache).tile_blob(raster::Layer::road_distance, col, row);
    return {bytes.begin(), bytes.end()};
  }
};

TEST(ServiceReload, AReplacedCacheIsServedFromTheNextRequestOn) {
  TwoBuilds builds;
  const auto served = builds.dir / "valley.gpkg";
  std::filesystem::copy_file(builds.a, served);
  std::vector<std::string> reloads;
  ServiceOptions options;
  options.reload_check_s = 0;
  options.on_reload = [&](const std::string& id, const std::string& error) { reloads.push_back(id + ":" + error); };
  Service service({served}, options);
  Request request;
  request.path = "/regions/valley/road_distance/1/1.png";
  const Response before = service.handle(request);
  ASSERT_EQ(before.status, 200) << before.text();
  ASSERT_EQ(before.text(), TwoBuilds::blob(builds.a, 1, 1));
  ASSERT_NE(TwoBuilds::blob(builds.a, 1, 1), TwoBuilds::blob(builds.b, 1, 1)) << "the fixture must differ";
  const auto held = service.region("valley");  // as a request under way holds it

  // A new build renamed over the file, as preprocess --overwrite does.
  std::filesystem::copy_file(builds.b, builds.dir / "incoming.gpkg");
  std::filesystem::rename(builds.dir / "incoming.gpkg", served);
  const Response after = service.handle(request);
  ASSERT_EQ(after.status, 200) << after.text();
  EXPECT_EQ(after.text(), TwoBuilds::blob(builds.b, 1, 1)) << "not the response cached for the old file";
  auto etag = [](const Response& r) {
    for (const auto& [k, v] : r.headers) {
      if (k == "ETag") return v;
    }
    return std::string();
  };
  EXPECT_NE(etag(after), etag(before));
  EXPECT_EQ(reloads, std::vector<std::string>{"valley:"});
  // The old reader still reads the old file (its inode), whole.
  const auto old_blob = held->tile_blob(raster::Layer::road_distance, 1, 1);
  EXPECT_EQ(std::string(old_blob.begin(), old_blob.end()), TwoBuilds::blob(builds.a, 1, 1));

  // Something that is not a cache renamed over it: the last good one stays in service.
  std::ofstream(builds.dir / "junk") << "not a GeoPackage";
  std::filesystem::rename(builds.dir / "junk", served);
  const Response kept = service.handle(request);
  EXPECT_EQ(kept.status, 200);
  EXPECT_EQ(kept.text(), TwoBuilds::blob(builds.b, 1, 1));
  ASSERT_EQ(reloads.size(), 2u);
  EXPECT_NE(reloads[1].find(served.string()), std::string::npos) << reloads[1];
}

TEST(ServiceSetup, RefusesMissingCachesAndDuplicateIds) {
  EXPECT_THROW(Service({}, ServiceOptions{}), ServiceError);
  EXPECT_THROW(Service({"/nonexistent/region.gpkg"}, ServiceOptions{}), raster::CacheError);
  EXPECT_THROW(Service({monaco_cache(), monaco_cache()}, ServiceOptions{}), ServiceError);
}

// Each options struct refuses a bad value itself, naming the field (the CLI turns it into a usage
// error); the service checks its options before opening anything.
TEST(ServeOptions, ValidateNamesTheField) {
  auto message_of = [](auto&& f) -> std::string {
    try {
      f();
    } catch (const std::exception& e) {
      return e.what();
    }
    return "";
  };
  LayerOptions layers;
  EXPECT_NO_THROW(layers.validate());
  layers.prior_sigma_m = 0;
  EXPECT_NE(message_of([&] { layers.validate(); }).find("prior_sigma_m"), std::string::npos);

  ServiceOptions service;
  EXPECT_NO_THROW(service.validate());
  service.max_crop_m = -1;
  EXPECT_NE(message_of([&] { Service({"/no/such.gpkg"}, service); }).find("max_crop_m"), std::string::npos)
      << "checked before the cache is opened";
  service.max_crop_m = 100;
  service.tile_lru = 0;
  EXPECT_THROW(service.validate(), ServiceError);
  service.tile_lru = 1;
  service.layers.prior_sigma_m = -2;
  EXPECT_NE(message_of([&] { service.validate(); }).find("prior_sigma_m"), std::string::npos);

  ExportOptions exported;
  EXPECT_NO_THROW(exported.validate());
  exported.bbox = osm::GeoBox{10, 47, 9, 48};
  EXPECT_THROW(exported.validate(), ExportError);
  exported.bbox.reset();
  exported.layer_options.prior_sigma_m = std::nan("");
  EXPECT_NE(message_of([&] { exported.validate(); }).find("prior_sigma_m"), std::string::npos);
}

}  // namespace
}  // namespace seqloc::serve
