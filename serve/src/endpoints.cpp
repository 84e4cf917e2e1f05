// The endpoints: tiles, crops, points, the catalog, TileJSON and WMTS.
#include "seqloc/serve/service.hpp"

#include <cmath>
#include <sstream>

#include <nlohmann/json.hpp>

#include "seqloc/osm/classes.hpp"
#include "seqloc/serve/geotiff.hpp"
#include "seqloc/serve/web_mercator.hpp"
#include "service_internal.hpp"

namespace seqloc::serve {

Response Service::tile(Region& region, std::string_view layer_name_, std::string_view col_text, std::string_view file,
                       const Request& request) {
  const auto layer = parse_layer(layer_name_);
  if (!layer) return error_response(404, "no layer '" + std::string(layer_name_).substr(0, 100) + "' (classes, road_distance, road_prior)");
  const std::size_t dot = file.rfind('.');
  const std::string_view row_text = file.substr(0, dot == std::string_view::npos ? file.size() : dot);
  const std::string_view ext = dot == std::string_view::npos ? std::string_view() : file.substr(dot + 1);
  std::int64_t col = 0, row = 0;
  if (!detail::parse_index(col_text, col) || !detail::parse_index(row_text, row)) {
    return error_response(400, "tile column and row must be non-negative integers: " + request.path.substr(0, 200));
  }
  if (ext != "png" && ext != "tif" && ext != "npy") {
    return error_response(404, "tile format '" + std::string(ext).substr(0, 20) + "' (png, tif or npy)");
  }
  std::string style = "data";
  if (const std::string* s = detail::find_param(request, "style")) style = *s;
  if (style != "data" && style != "color") return error_response(400, "style: 'data' or 'color'");
  if (style == "color" && ext != "png") return error_response(400, "style=color is a PNG style");

  const std::string key = region.build_tag + "/" + region.id + "/" + layer_name(*layer) + "/" + std::to_string(col) + "/" + std::to_string(row) +
                          "." + std::string(ext) + "/" + style;
  return cached_tile(region, key, detail::content_type_of(ext), [&]() -> std::shared_ptr<const std::string> {
    require_tile(*region.cache, col, row);
    if (ext == "png" && style == "data" && *layer != MapLayer::road_prior) {
      // The stored blob is already this PNG: no decoding, no encoding.
      const auto blob = region.cache->tile_blob(
          *layer == MapLayer::classes ? raster::Layer::classes : raster::Layer::road_distance, col, row);
      return std::make_shared<const std::string>(blob.begin(), blob.end());
    }
    const MapBlock block = read_tile(*region.cache, *layer, col, row, options_.layers);
    if (ext == "npy") return std::make_shared<const std::string>(encode_npy(block));
    if (ext == "tif") {
      return std::make_shared<const std::string>(encode_geotiff(block, region.cache->metadata().projection()));
    }
    const auto png = style == "color" ? encode_styled_png(block) : encode_data_png(block);
    return std::make_shared<const std::string>(png.begin(), png.end());
  });
}

Response Service::cached_tile(const Region& region, const std::string& key, std::string content_type,
                              const std::function<std::shared_ptr<const std::string>()>& encode) {
  {
    std::lock_guard lock(cache_mutex_);
    if (const Response* hit = responses_.find(key)) {
      ++cache_hits_;
      return *hit;
    }
  }
  Response r;
  r.content_type = std::move(content_type);
  r.body = encode();
  r.headers.emplace_back("ETag", "\"" + region.build_tag + "-" + detail::hex(detail::fnv1a(key)) + "\"");
  r.headers.emplace_back("Cache-Control", "public, max-age=" + std::to_string(options_.tile_max_age_s));
  std::lock_guard lock(cache_mutex_);
  if (r.body->size() <= options_.response_cache_bytes / 8) responses_.insert(key, r);
  return r;
}

Response Service::xyz_tile(Region& region, std::string_view layer_text, std::string_view z_text,
                           std::string_view x_text, std::string_view file, const Request& request) {
  const auto layer = parse_layer(layer_text);
  if (!layer) {
    return error_response(404, "no layer '" + std::string(layer_text).substr(0, 100) + "' (classes, road_distance, road_prior)");
  }
  // {y}.png (256 px) or {y}@2x.png (512 px, the same ground).
  const auto stem = detail::strip_suffix(file, ".png");
  if (!stem) return error_response(404, "XYZ tiles are PNG: {y}.png or {y}@2x.png");
  const auto retina = detail::strip_suffix(*stem, "@2x");
  const std::string_view y_text = retina.value_or(*stem);
  const int tile_px = retina ? 512 : 256;
  std::int64_t z = 0, x = 0, y = 0;
  if (!detail::parse_index(z_text, z) || !detail::parse_index(x_text, x) || !detail::parse_index(y_text, y) || z > 30) {
    return error_response(400, "z, x and y must be non-negative integers (z at most 30): " + request.path.substr(0, 200));
  }
  // Web maps want pictures: 'color' unless the data is asked for.
  std::string style = "color";
  if (const std::string* s = detail::find_param(request, "style")) style = *s;
  if (style != "data" && style != "color") return error_response(400, "style: 'data' or 'color'");

  const std::string key = region.build_tag + "/" + region.id + "/xyz/" + layer_name(*layer) + "/" + std::to_string(z) +
                          "/" + std::to_string(x) + "/" + std::to_string(y) + "/" + std::to_string(tile_px) + "/" + style;
  return cached_tile(region, key, "image/png", [&] {
    const WebTile tile = read_web_tile(*region.cache, *layer, static_cast<int>(z), x, y, tile_px, options_.layers);
    const auto png = style == "color" ? encode_styled_png(tile.block, tile.covered) : encode_data_png(tile.block);
    return std::make_shared<const std::string>(png.begin(), png.end());
  });
}

namespace {

// A crop's sidecar: what the crop of `block` holds and where, as JSON.
Response crop_sidecar(const std::string& region_id, const raster::CacheMetadata& m, const MapBlock& block,
                      const std::string& format, double prior_sigma_m) {
  double gamma = 0;
  const osm::GeoPoint centre = m.projection().reverse({block.centre_x_m(), block.centre_y_m()}, gamma);
  ordered_json bands = ordered_json::array();
  for (const auto& b : block.bands) bands.push_back(b.name);
  const bool u8 = block.all_uint8();
  const std::string dtype =
      format == "png" ? (block.layers[0] == MapLayer::classes ? "uint8" : "uint16") : (u8 ? "uint8" : "float32");
  return detail::json_response({
      {"region", region_id},
      {"crs", "region"},
      {"crs_wkt", m.projection().wkt()},
      {"crs_proj", m.projection().proj_string()},
      {"crop_x", block.centre_x_m()},
      {"crop_y", block.centre_y_m()},
      {"crop_lat", centre.lat_deg},
      {"crop_lon", centre.lon_deg},
      {"meridian_convergence_deg", gamma},
      {"cell_m", raster::kCellM},
      {"width", block.width},
      {"height", block.height},
      {"west_m", block.west_m},
      {"north_m", block.north_m},
      {"geotransform", {block.west_m, raster::kCellM, 0, block.north_m, 0, -raster::kCellM}},
      {"bands", bands},
      {"dtype", dtype},
      {"outside_cells", block.outside_cells},
      {"road_distance_max_m", m.max_distance_m},
      {"road_prior_sigma_m", prior_sigma_m},
  });
}

// A crop's data in `format` (npy, tif or png), its georeference in headers.
Response crop_data(const std::string& region_id, const raster::CacheMetadata& m, const MapBlock& block,
                   const std::string& format, int max_age_s) {
  Response r;
  std::string band_names;
  for (const auto& b : block.bands) band_names += (band_names.empty() ? "" : ",") + b.name;
  r.content_type = detail::content_type_of(format);
  if (format == "npy") {
    r.body = std::make_shared<const std::string>(encode_npy(block));
  } else if (format == "tif") {
    r.body = std::make_shared<const std::string>(encode_geotiff(block, m.projection()));
  } else {
    const auto png = encode_data_png(block);
    r.body = std::make_shared<const std::string>(png.begin(), png.end());
  }
  r.headers.emplace_back("Cache-Control", "public, max-age=" + std::to_string(max_age_s));
  r.headers.emplace_back("X-Seqloc-Region", region_id);
  r.headers.emplace_back("X-Seqloc-Crop-X", detail::fixed(block.centre_x_m(), 3));
  r.headers.emplace_back("X-Seqloc-Crop-Y", detail::fixed(block.centre_y_m(), 3));
  r.headers.emplace_back("X-Seqloc-Cell-M", detail::fixed(raster::kCellM, 3));
  r.headers.emplace_back("X-Seqloc-Shape", std::to_string(block.height) + "," + std::to_string(block.width) + "," +
                                               std::to_string(block.bands.size()));
  r.headers.emplace_back("X-Seqloc-Bands", band_names);
  r.headers.emplace_back("X-Seqloc-Geotransform",
                         detail::fixed(block.west_m, 3) + ",0.5,0," + detail::fixed(block.north_m, 3) + ",0,-0.5");
  r.headers.emplace_back("X-Seqloc-Crs", m.projection().proj_string());
  r.headers.emplace_back("X-Seqloc-Outside-Cells", std::to_string(block.outside_cells));
  return r;
}

}  // namespace

Response Service::crop(Region& region, const Request& request, bool sidecar_only) {
  const double lat = detail::number_param(request, "lat");
  const double lon = detail::number_param(request, "lon");
  const double size_m = detail::number_param(request, "size_m", 128.0);
  const std::string* layers_text = detail::find_param(request, "layers");
  const auto layers = parse_layer_list(layers_text ? *layers_text : "classes,road_distance,road_prior");
  const std::string* format_text = detail::find_param(request, "format");
  const std::string format = format_text ? *format_text : "npy";
  if (format != "npy" && format != "tif" && format != "png") {
    throw RequestError(RequestError::Kind::bad_request, "format: '" + format.substr(0, 20) + "' (npy, tif or png)");
  }
  if (format == "png" && layers.size() != 1) {
    throw RequestError(RequestError::Kind::bad_request, "format=png holds one layer; ask for one, or use npy or tif");
  }
  // A sidecar describes the crop without reading it.
  const MapBlock block = [&] {
    if (!sidecar_only) return read_crop(*region.cache, lat, lon, size_m, layers, options_.layers, options_.max_crop_m);
    const CropWindow w = raster::locate_crop(*region.cache, lat, lon, size_m, options_.max_crop_m);
    return describe_block(*region.cache, w.u0, w.v0, w.size, w.size, layers);
  }();
  const auto& m = region.cache->metadata();
  std::string canonical;
  for (const auto& [k, v] : request.query) canonical.append(k).append("=").append(v).append("&");
  const std::string etag = "\"" + region.build_tag + "-" + detail::hex(detail::fnv1a(canonical + (sidecar_only ? "json" : ""))) + "\"";
  Response r = sidecar_only ? crop_sidecar(region.id, m, block, format, options_.layers.prior_sigma_m)
                            : crop_data(region.id, m, block, format, options_.tile_max_age_s);
  r.headers.emplace_back("ETag", etag);
  return r;
}

Response Service::point(Region& region, std::string_view where) {
  const std::size_t comma = where.find(',');
  double lon = 0, lat = 0;
  if (comma == std::string_view::npos || !detail::parse_number(where.substr(0, comma), lon) ||
      !detail::parse_number(where.substr(comma + 1), lat) || std::abs(lat) > 90 || std::abs(lon) > 180) {
    throw RequestError(RequestError::Kind::bad_request, "point: expected /point/LON,LAT in degrees");
  }
  const auto& m = region.cache->metadata();
  const auto& g = m.grid;
  const auto p = m.projection().forward({lat, lon});
  const double u = g.region_u(p.x_m), v = g.region_v(p.y_m);
  const auto cu = static_cast<std::int64_t>(std::floor(u + 0.5)), cv = static_cast<std::int64_t>(std::floor(v + 0.5));
  if (!(u > -0.5 && v > -0.5 && cu < g.width_px() && cv < g.height_px())) {
    throw RequestError(RequestError::Kind::not_found,
                       "the point (" + detail::fixed(lon, 7) + ", " + detail::fixed(lat, 7) + ") is outside region '" + region.id + "'");
  }
  const CellValues values = read_cell(*region.cache, cu, cv, options_.layers);
  ordered_json classes = ordered_json::object();
  for (int c = 0; c < osm::kChannelCount; ++c) {
    const auto channel = static_cast<osm::Channel>(c);
    const int code = values.classes[c];
    const auto names = osm::group_names(channel);
    classes[std::string(osm::channel_name(channel))] = {
        {"code", code},
        {"name", code == 0 ? "background" : (static_cast<std::size_t>(code) <= names.size() ? std::string(names[static_cast<std::size_t>(code - 1)]) : "unknown")}};
  }
  return detail::json_response({{"region", region.id},
                        {"lon", lon},
                        {"lat", lat},
                        {"x", p.x_m},
                        {"y", p.y_m},
                        {"cell", {cu, cv}},
                        {"classes", classes},
                        {"road_distance_m", values.road_distance_m},
                        {"road_prior", values.road_prior},
                        {"road_prior_sigma_m", options_.layers.prior_sigma_m}});
}

Response Service::catalog(const Request& request) {
  ordered_json regions = ordered_json::array();
  for (const auto& [id, slot] : regions_) {
    const auto region = current(*slot);
    const auto& m = region->cache->metadata();
    regions.push_back({{"id", id},
                       {"source_file", m.source_file},
                       {"source_sha256", m.source_sha256},
                       {"created_utc", m.created_utc},
                       {"bounds", {region->bounds.min_lon, region->bounds.min_lat, region->bounds.max_lon, region->bounds.max_lat}},
                       {"center", {m.centre_lon, m.centre_lat}},
                       {"layers", {"classes", "road_distance", "road_prior"}},
                       {"tiles", {{"columns", m.grid.tiles_wide()}, {"rows", m.grid.tiles_high()}}},
                       {"tilejson", request.base_url + "/regions/" + id + "/tilejson.json"},
                       {"wmts", request.base_url + "/regions/" + id + "/wmts.xml"}});
  }
  return detail::json_response({{"regions", regions}, {"attribution", "Map data (c) OpenStreetMap contributors, ODbL 1.0"}});
}

Response Service::tilejson(const Region& region, const Request& request) const {
  const auto& m = region.cache->metadata();
  const auto& g = m.grid;
  const std::string base = request.base_url + "/regions/" + region.id;
  const WebZooms zooms = web_zooms(m);
  ordered_json layers = ordered_json::object();
  for (MapLayer layer : kAllLayers) {
    const std::string name = layer_name(layer);
    std::string xyz = base, region_tiles = base;
    xyz.append("/xyz/").append(name).append("/{z}/{x}/{y}.png");
    region_tiles.append("/").append(name).append("/{x}/{y}.png");
    layers[name] = {{"tiles", {xyz}},
                    {"region_tiles", region_tiles},
                    {"formats", {"png", "tif", "npy"}},
                    {"styles", {"data", "color"}}};
  }
  // The standard fields describe the Web Mercator XYZ tiles (what web maps read); `crs` and
  // `tile_matrix` describe the region's own tiles (what the viewer and GIS read).
  return detail::json_response(
      {{"tilejson", "3.0.0"},
       {"name", region.id},
       {"description", "seqloc region cache of " + m.source_file +
                           ": XYZ tiles in Web Mercator, and the region's own tiles (crs, tile_matrix)"},
       {"attribution", "Map data (c) OpenStreetMap contributors, ODbL 1.0"},
       {"scheme", "xyz"},
       {"tiles", {base + "/xyz/classes/{z}/{x}/{y}.png"}},
       {"minzoom", zooms.min_zoom},
       {"maxzoom", zooms.max_zoom},
       {"bounds", {region.bounds.min_lon, region.bounds.min_lat, region.bounds.max_lon, region.bounds.max_lat}},
       {"center", {m.centre_lon, m.centre_lat, zooms.max_zoom - 1}},
       {"crs", {{"wkt", m.projection().wkt()}, {"proj", m.projection().proj_string()}}},
       {"tile_matrix",
        {{"tile_size", raster::kTilePx},
         {"cell_m", raster::kCellM},
         {"top_left", {g.min_x(), g.max_y()}},
         {"extent", {g.min_x(), g.min_y(), g.max_x(), g.max_y()}},
         {"columns", g.tiles_wide()},
         {"rows", g.tiles_high()}}},
       {"layers", layers},
       {"road_distance_max_m", m.max_distance_m},
       {"road_prior_sigma_m", options_.layers.prior_sigma_m},
       {"crop", base + "/crop?lat={lat}&lon={lon}&size_m=128&layers=classes,road_distance,road_prior&format=npy"},
       {"point", base + "/point/{lon},{lat}"}});
}

Response Service::wmts(const Region& region, const Request& request) const {
  const auto& m = region.cache->metadata();
  const auto& g = m.grid;
  const std::string base = request.base_url + "/regions/" + region.id;
  const std::string matrix_set = "seqloc-" + region.id;
  // Scale denominator of 0.5 m cells at the standard 0.28 mm rendering pixel (WMTS 1.0.0, 6.1).
  const double scale = raster::kCellM / 0.00028;
  std::ostringstream x;
  x.precision(17);
  x << "<?xml version=\"1.0\" encoding=\"UTF-8\"?>\n"
    << "<Capabilities xmlns=\"http://www.opengis.net/wmts/1.0\" xmlns:ows=\"http://www.opengis.net/ows/1.1\" "
       "xmlns:xlink=\"http://www.w3.org/1999/xlink\" version=\"1.0.0\">\n"
    << "  <ows:ServiceIdentification><ows:Title>seqloc " << region.id
    << "</ows:Title><ows:ServiceType>OGC WMTS</ows:ServiceType><ows:ServiceTypeVersion>1.0.0</ows:ServiceTypeVersion>"
       "<ows:AccessConstraints>Map data (c) OpenStreetMap contributors, ODbL 1.0</ows:AccessConstraints>"
       "</ows:ServiceIdentification>\n"
    << "  <Contents>\n";
  for (MapLayer layer : kAllLayers) {
    const std::string name = layer_name(layer);
    x << "    <Layer><ows:Title>" << name << "</ows:Title><ows:Identifier>" << name << "</ows:Identifier>"
      << "<ows:WGS84BoundingBox><ows:LowerCorner>" << region.bounds.min_lon << " " << region.bounds.min_lat
      << "</ows:LowerCorner><ows:UpperCorner>" << region.bounds.max_lon << " " << region.bounds.max_lat
      << "</ows:UpperCorner></ows:WGS84BoundingBox>"
      << R"(<Style isDefault="true"><ows:Identifier>data</ows:Identifier></Style>)"
      << "<Style><ows:Identifier>color</ows:Identifier></Style>"
      << "<Format>image/png</Format>" << (layer == MapLayer::classes ? "" : "<Format>image/tiff</Format>")
      << "<TileMatrixSetLink><TileMatrixSet>" << matrix_set << "</TileMatrixSet></TileMatrixSetLink>"
      << R"(<ResourceURL format="image/png" resourceType="tile" template=")" << base << "/" << name
      << "/{TileCol}/{TileRow}.png?style={Style}\"/>";
    // Metres and priors as Float32 GeoTIFF tiles: GDAL's WMTS client decodes them as data (it
    // reads any PNG as 8-bit RGBA unless told otherwise; wmts/LAYER.xml tells it).
    if (layer != MapLayer::classes) {
      x << R"(<ResourceURL format="image/tiff" resourceType="tile" template=")" << base << "/" << name
        << "/{TileCol}/{TileRow}.tif\"/>";
    }
    x << "</Layer>\n";
  }
  x << "    <TileMatrixSet><ows:Identifier>" << matrix_set << "</ows:Identifier>"
    << "<ows:SupportedCRS>" << m.projection().proj_string() << "</ows:SupportedCRS>"
    << "<TileMatrix><ows:Identifier>0</ows:Identifier><ScaleDenominator>" << scale << "</ScaleDenominator>"
    << "<TopLeftCorner>" << g.min_x() << " " << g.max_y() << "</TopLeftCorner>"
    << "<TileWidth>" << raster::kTilePx << "</TileWidth><TileHeight>" << raster::kTilePx << "</TileHeight>"
    << "<MatrixWidth>" << g.tiles_wide() << "</MatrixWidth><MatrixHeight>" << g.tiles_high() << "</MatrixHeight>"
    << "</TileMatrix></TileMatrixSet>\n"
    << "  </Contents>\n</Capabilities>\n";
  return detail::xml_response(x.str());
}

Response Service::gdal_wmts(const Region& region, std::string_view file, const Request& request) const {
  // GDAL's WMTS client reads every layer as 4 bands of Byte unless a service description says
  // otherwise: this one names the layer, its format, band count and type, and no local cache.
  const auto layer = parse_layer(detail::strip_suffix(file, ".xml").value_or(""));
  if (!layer) {
    return error_response(404, "no GDAL service description '" + std::string(file).substr(0, 100) +
                                   "': wmts/classes.xml, wmts/road_distance.xml or wmts/road_prior.xml");
  }
  const bool classes = *layer == MapLayer::classes;
  std::ostringstream x;
  x << "<GDAL_WMTS>\n"
    << "  <GetCapabilitiesUrl>" << request.base_url << "/regions/" << region.id << "/wmts.xml</GetCapabilitiesUrl>\n"
    << "  <Layer>" << layer_name(*layer) << "</Layer>\n"
    << "  <Style>data</Style>\n"
    << "  <TileMatrixSet>seqloc-" << region.id << "</TileMatrixSet>\n"
    << "  <Format>" << (classes ? "image/png" : "image/tiff") << "</Format>\n"
    << "  <BandsCount>" << (classes ? 3 : 1) << "</BandsCount>\n"
    << "  <DataType>" << (classes ? "Byte" : "Float32") << "</DataType>\n"
    << "</GDAL_WMTS>\n";
  return detail::xml_response(x.str());
}

}  // namespace seqloc::serve
