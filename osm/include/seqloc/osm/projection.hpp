#pragma once
// The region CRS (conventions.md section 1): Transverse Mercator on WGS84 centred on the region,
// scale factor 1, metres, no false easting/northing. GeographicLib does the projection.

#include <string>

#include <GeographicLib/TransverseMercator.hpp>

namespace seqloc::osm {

struct GeoPoint {
  double lat_deg = 0;
  double lon_deg = 0;
};

struct GridPoint {
  double x_m = 0;  ///< east of the region centre (grid east)
  double y_m = 0;  ///< north of the region centre (grid north)
};

class RegionProjection {
 public:
  RegionProjection(double lat0_deg, double lon0_deg);

  [[nodiscard]] GridPoint forward(GeoPoint p) const;
  /// Also returns the meridian convergence gamma (degrees): grid north is rotated by gamma
  /// clockwise from true north, so compass = grid heading + gamma.
  [[nodiscard]] GridPoint forward(GeoPoint p, double& gamma_deg) const;
  [[nodiscard]] GeoPoint reverse(GridPoint p) const;
  [[nodiscard]] GeoPoint reverse(GridPoint p, double& gamma_deg) const;
  /// The point scale k at a grid point: a grid metre there is 1 / k metres on the ground. It is 1
  /// on the central meridian and grows with the distance east or west of it (about
  /// 1 + x^2 / (2 R^2): 1.001 at 285 km).
  [[nodiscard]] double scale(GridPoint p) const;

  [[nodiscard]] double lat0_deg() const { return lat0_; }
  [[nodiscard]] double lon0_deg() const { return lon0_; }
  /// OGC WKT 1 of the CRS, as stored in the cache; GDAL and QGIS read it unchanged.
  [[nodiscard]] std::string wkt() const;
  /// The equivalent PROJ string (documentation and cross-checks with PROJ-based tools).
  [[nodiscard]] std::string proj_string() const;

 private:
  double lat0_;
  double lon0_;
  double y0_ = 0;  ///< northing of the origin latitude from the equator
  GeographicLib::TransverseMercator tm_;
};

}  // namespace seqloc::osm
