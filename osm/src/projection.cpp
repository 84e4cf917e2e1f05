#include "seqloc/osm/projection.hpp"

#include <cstdio>

#include <GeographicLib/Constants.hpp>

namespace seqloc::osm {

RegionProjection::RegionProjection(double lat0_deg, double lon0_deg)
    : lat0_(lat0_deg),
      lon0_(lon0_deg),
      tm_(GeographicLib::Constants::WGS84_a(), GeographicLib::Constants::WGS84_f(), 1.0) {
  double x = 0;
  tm_.Forward(lon0_, lat0_, lon0_, x, y0_);
}

GridPoint RegionProjection::forward(GeoPoint p) const {
  double gamma = 0;
  return forward(p, gamma);
}

GridPoint RegionProjection::forward(GeoPoint p, double& gamma_deg) const {
  double x = 0, y = 0, k = 0;
  tm_.Forward(lon0_, p.lat_deg, p.lon_deg, x, y, gamma_deg, k);
  return {x, y - y0_};
}

GeoPoint RegionProjection::reverse(GridPoint p) const {
  double gamma = 0;
  return reverse(p, gamma);
}

GeoPoint RegionProjection::reverse(GridPoint p, double& gamma_deg) const {
  double lat = 0, lon = 0, k = 0;
  tm_.Reverse(lon0_, p.x_m, p.y_m + y0_, lat, lon, gamma_deg, k);
  return {lat, lon};
}

double RegionProjection::scale(GridPoint p) const {
  double lat = 0, lon = 0, gamma = 0, k = 0;
  tm_.Reverse(lon0_, p.x_m, p.y_m + y0_, lat, lon, gamma, k);
  return k;
}

std::string RegionProjection::wkt() const {
  char buffer[1024];
  std::snprintf(buffer, sizeof buffer,
                "PROJCS[\"seqloc region TM %.9f %.9f\",GEOGCS[\"WGS 84\",DATUM[\"WGS_1984\",SPHEROID[\"WGS 84\","
                "6378137,298.257223563,AUTHORITY[\"EPSG\",\"7030\"]],AUTHORITY[\"EPSG\",\"6326\"]],PRIMEM["
                "\"Greenwich\",0,AUTHORITY[\"EPSG\",\"8901\"]],UNIT[\"degree\",0.0174532925199433,AUTHORITY["
                "\"EPSG\",\"9122\"]],AUTHORITY[\"EPSG\",\"4326\"]],PROJECTION[\"Transverse_Mercator\"],"
                "PARAMETER[\"latitude_of_origin\",%.12g],PARAMETER[\"central_meridian\",%.12g],PARAMETER["
                "\"scale_factor\",1],PARAMETER[\"false_easting\",0],PARAMETER[\"false_northing\",0],UNIT["
                "\"metre\",1,AUTHORITY[\"EPSG\",\"9001\"]],AXIS[\"Easting\",EAST],AXIS[\"Northing\",NORTH]]",
                lat0_, lon0_, lat0_, lon0_);
  return buffer;
}

std::string RegionProjection::proj_string() const {
  char buffer[256];
  std::snprintf(buffer, sizeof buffer,
                "+proj=tmerc +lat_0=%.12g +lon_0=%.12g +k=1 +x_0=0 +y_0=0 +datum=WGS84 +units=m +no_defs", lat0_,
                lon0_);
  return buffer;
}

}  // namespace seqloc::osm
