// The region CRS against GeographicLib's exact Transverse Mercator (a different algorithm: Lee's
// elliptic-function formulation, not Krueger's series), plus round trips and convergence.

#include <cmath>

#include <GeographicLib/Constants.hpp>
#include <GeographicLib/Geodesic.hpp>
#include <GeographicLib/TransverseMercatorExact.hpp>
#include <gtest/gtest.h>

#include "seqloc/osm/projection.hpp"

namespace seqloc::osm {
namespace {

TEST(Projection, OriginIsZero) {
  const RegionProjection p(42.5, 1.6);
  const auto g = p.forward({42.5, 1.6});
  EXPECT_NEAR(g.x_m, 0.0, 1e-9);
  EXPECT_NEAR(g.y_m, 0.0, 1e-9);
}

TEST(Projection, AgreesWithExactTransverseMercator) {
  const RegionProjection p(50.0, 11.5);
  const GeographicLib::TransverseMercatorExact exact(GeographicLib::Constants::WGS84_a(),
                                                     GeographicLib::Constants::WGS84_f(), 1.0);
  double x0 = 0, y0 = 0;
  exact.Forward(11.5, 50.0, 11.5, x0, y0);
  for (double dlat : {-0.5, 0.0, 0.3}) {
    for (double dlon : {-0.7, 0.0, 0.4}) {
      double x = 0, y = 0;
      exact.Forward(11.5, 50.0 + dlat, 11.5 + dlon, x, y);
      const auto g = p.forward({50.0 + dlat, 11.5 + dlon});
      // Krueger's 6th-order series is accurate to 5 nm within 3,900 km of the central meridian.
      EXPECT_NEAR(g.x_m, x, 1e-6);
      EXPECT_NEAR(g.y_m, y - y0, 1e-6);
    }
  }
}

TEST(Projection, RoundTripsAndReportsConvergence) {
  const RegionProjection p(42.5, 1.6);
  const GeoPoint far{42.6, 1.9};  // ~25 km east of the centre
  double gamma = 0;
  const auto g = p.forward(far, gamma);
  const auto back = p.reverse(g);
  EXPECT_NEAR(back.lat_deg, far.lat_deg, 1e-11);
  EXPECT_NEAR(back.lon_deg, far.lon_deg, 1e-11);
  // gamma ~ dlon * sin(lat) for small dlon: 0.3 * sin(42.6 deg) = 0.203 deg.
  EXPECT_NEAR(gamma, 0.3 * std::sin(42.6 * M_PI / 180.0), 0.002);
  EXPECT_GT(std::abs(gamma), 0.1);
}

// The point scale, measured independently: 10 grid metres along x against the geodesic length
// of the same two points on the ellipsoid. It grows as about 1 + x^2 / (2 R^2): 0.1 % at 285 km,
// the bound preprocess puts on a region's edge.
TEST(Projection, ScaleIsTheRatioOfGridToGroundDistance) {
  const RegionProjection p(50.0, 11.5);
  const auto& geodesic = GeographicLib::Geodesic::WGS84();
  for (double x : {0.0, 100'000.0, 285'000.0, -285'000.0}) {
    for (double y : {-300'000.0, 0.0, 250'000.0}) {
      const GeoPoint a = p.reverse({x - 5.0, y}), b = p.reverse({x + 5.0, y});
      double ground = 0;
      geodesic.Inverse(a.lat_deg, a.lon_deg, b.lat_deg, b.lon_deg, ground);
      EXPECT_NEAR(p.scale({x, y}), 10.0 / ground, 1e-8) << x << ", " << y;
    }
    const double r = 6'371'000.0;
    EXPECT_NEAR(p.scale({x, 0.0}), 1.0 + x * x / (2 * r * r), 2e-5) << x;
  }
  EXPECT_GT(p.scale({285'000.0, 0.0}) - 1.0, 0.00099);
  EXPECT_LT(p.scale({280'000.0, 0.0}) - 1.0, 0.001);
}

TEST(Projection, WktNamesTheParameters) {
  const RegionProjection p(42.5, 1.6);
  const auto wkt = p.wkt();
  EXPECT_NE(wkt.find("Transverse_Mercator"), std::string::npos);
  EXPECT_NE(wkt.find("PARAMETER[\"latitude_of_origin\",42.5]"), std::string::npos);
  EXPECT_NE(wkt.find("PARAMETER[\"central_meridian\",1.6]"), std::string::npos);
  EXPECT_NE(p.proj_string().find("+proj=tmerc +lat_0=42.5 +lon_0=1.6 +k=1"), std::string::npos);
}

}  // namespace
}  // namespace seqloc::osm
