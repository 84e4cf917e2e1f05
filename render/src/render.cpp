#include "seqloc/render/render.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <optional>
#include <stdexcept>

#include <opencv2/imgproc.hpp>

#include "seqloc/core/angles.hpp"
#include "seqloc/core/files.hpp"
#include "seqloc/core/flat_index.hpp"
#include "seqloc/core/units.hpp"
#include "seqloc/io/npy.hpp"
#include "seqloc/io/run_folder.hpp"
#include "seqloc/osm/classes.hpp"
#include "seqloc/raster/palette.hpp"
#include "seqloc/raster/png_codec.hpp"

namespace seqloc::render {
namespace {

using core::kCellM;

using Rgb = cv::Vec3b;

cv::Mat to_mat(Picture& p) { return {p.height, p.width, CV_8UC3, p.rgb.data()}; }

Picture from_mat(const cv::Mat& m) {
  Picture p;
  p.width = m.cols;
  p.height = m.rows;
  p.rgb.assign(m.data, m.data + static_cast<std::size_t>(m.total() * 3));
  if (!m.isContinuous()) {
    for (int r = 0; r < m.rows; ++r)
      std::memcpy(p.rgb.data() + static_cast<std::size_t>(r) * static_cast<std::size_t>(m.cols) * 3, m.ptr(r),
                  static_cast<std::size_t>(m.cols) * 3);
  }
  return p;
}

cv::Scalar rgb(double r, double g, double b) { return {r, g, b}; }  // our Mats hold RGB

void text(cv::Mat& m, const std::string& s, cv::Point at, double scale = 0.45,
          const cv::Scalar& colour = rgb(0, 0, 0)) {
  cv::putText(m, s, at, cv::FONT_HERSHEY_SIMPLEX, scale, colour, 1, cv::LINE_AA);
}

// Viridis-like colour for t in [0, 1], RGB.
cv::Scalar viridis(double t) {
  static const double stops[5][3] = {{68, 1, 84}, {59, 82, 139}, {33, 145, 140}, {94, 201, 98}, {253, 231, 37}};
  t = std::clamp(t, 0.0, 1.0) * 4;
  const int i = std::min(3, static_cast<int>(t));
  const double f = t - i;
  return rgb(static_cast<int>(stops[i][0] + f * (stops[i + 1][0] - stops[i][0])),
             static_cast<int>(stops[i][1] + f * (stops[i + 1][1] - stops[i][1])),
             static_cast<int>(stops[i][2] + f * (stops[i + 1][2] - stops[i][2])));
}

void star(cv::Mat& m, cv::Point2d c, double r) {
  std::vector<cv::Point> pts;
  for (int k = 0; k < 10; ++k) {
    const double a = -core::kPi / 2 + k * core::kPi / 5, rr = k % 2 ? r * 0.45 : r;
    pts.emplace_back(static_cast<int>(std::lround(c.x + rr * std::cos(a))),
                     static_cast<int>(std::lround(c.y + rr * std::sin(a))));
  }
  // An outline, so that the belief under it stays visible.
  cv::polylines(m, std::vector<std::vector<cv::Point>>{pts}, true, rgb(0, 0, 0), 3, cv::LINE_AA);
  cv::polylines(m, std::vector<std::vector<cv::Point>>{pts}, true, rgb(255, 215, 0), 1, cv::LINE_AA);
}

// Red over the map, opacity growing from the median mass (transparent) to the largest (square
// root: the tails stay visible; the median: a nearly flat likelihood does not paint everything).
void overlay_mass(cv::Mat& m, const std::vector<double>& mass) {
  std::vector<double> sorted = mass;
  std::nth_element(sorted.begin(), sorted.begin() + static_cast<std::ptrdiff_t>(sorted.size() / 2), sorted.end());
  const double floor = sorted[sorted.size() / 2];
  const double top = *std::max_element(mass.begin(), mass.end());
  if (!(top > floor)) return;
  for (int v = 0; v < m.rows; ++v) {
    for (int u = 0; u < m.cols; ++u) {
      const double a = 0.85 * std::sqrt(std::max(0.0, mass[core::flat(v, u, m.cols)] - floor) / (top - floor));
      auto& px = m.at<Rgb>(v, u);
      px =
          Rgb(static_cast<std::uint8_t>((1 - a) * px[0] + a * 230), static_cast<std::uint8_t>((1 - a) * px[1] + a * 20),
              static_cast<std::uint8_t>((1 - a) * px[2] + a * 20));
    }
  }
}

cv::Mat upscale(const cv::Mat& m, int factor) {
  cv::Mat out;
  cv::resize(m, out, cv::Size(), factor, factor, cv::INTER_NEAREST);
  return out;
}

std::string fmt(double v, int digits) {
  char b[64];
  std::snprintf(b, sizeof b, "%.*f", digits, v);
  return b;
}

double nice_step(double range) {
  const double raw = range / 5, p = std::pow(10.0, std::floor(std::log10(raw)));
  for (double m : {1.0, 2.0, 5.0, 10.0}) {
    if (m * p >= raw) return m * p;
  }
  return 10 * p;
}

// What a legend shows of one item.
struct LegendItem {
  enum class Shape { swatch, line, dot, star };
  std::string name;
  cv::Scalar colour;
  Shape shape = Shape::swatch;
};

cv::Scalar scalar(const std::array<std::uint8_t, 3>& c) { return rgb(c[0], c[1], c[2]); }

cv::Scalar class_colour(std::uint8_t area, std::uint8_t way, std::uint8_t node) {
  const std::array<std::uint8_t, 3> codes{area, way, node};
  const auto c = raster::class_colours(codes);
  return rgb(c[0], c[1], c[2]);
}

// Which codes of each channel (areas, ways, nodes) occur in a map.
using SeenClasses = std::array<std::array<bool, 256>, 3>;
void note_classes(std::span<const std::uint8_t> classes, SeenClasses& seen) {
  for (std::size_t i = 0; i + 2 < classes.size(); i += 3) {
    for (std::size_t c = 0; c < 3; ++c) seen[c][classes[i + c]] = true;
  }
}

// The map classes seen, named, in the map's colours: areas, then ways, then nodes.
std::vector<LegendItem> classes_legend(const SeenClasses& seen) {
  std::vector<LegendItem> items;
  auto add = [&](osm::Channel channel, std::size_t code, const cv::Scalar& colour) {
    const auto names = osm::group_names(channel);
    if (code >= 1 && code <= names.size()) items.push_back({std::string(names[code - 1]), colour});
  };
  for (std::size_t code = 1; code < 256; ++code) {
    if (seen[0][code]) add(osm::Channel::areas, code, class_colour(static_cast<std::uint8_t>(code), 0, 0));
  }
  for (std::size_t code = 1; code < 256; ++code) {
    // Building outlines are drawn around every building: the building's entry says enough.
    if (seen[1][code] && code != osm::kBuildingOutline.code()) {
      add(osm::Channel::ways, code, class_colour(0, static_cast<std::uint8_t>(code), 0));
    }
  }
  if (seen[2][1]) add(osm::Channel::nodes, 1, class_colour(0, 0, 1));
  if (std::any_of(seen[2].begin() + 2, seen[2].end(), [](bool b) { return b; })) {
    items.push_back({"other nodes", class_colour(0, 0, 2)});
  }
  return items;
}

// The legend's items in rows `width` wide.
cv::Mat legend_strip(const std::vector<LegendItem>& items, int width) {
  constexpr double kText = 0.42;
  constexpr int kRow = 22, kSymbol = 18;
  std::vector<std::pair<cv::Point, const LegendItem*>> placed;
  int x = 8, y = 16;
  for (const auto& item : items) {
    int baseline = 0;
    const int w = kSymbol + 5 + cv::getTextSize(item.name, cv::FONT_HERSHEY_SIMPLEX, kText, 1, &baseline).width + 16;
    if (x > 8 && x + w > width) x = 8, y += kRow;
    placed.emplace_back(cv::Point(x, y), &item);
    x += w;
  }
  cv::Mat m(items.empty() ? 0 : y + 10, width, CV_8UC3, rgb(255, 255, 255));
  for (const auto& [at, item] : placed) {
    const cv::Point mid = at + cv::Point(kSymbol / 2, -4);
    switch (item->shape) {
      case LegendItem::Shape::swatch:
        cv::rectangle(m, at + cv::Point(0, -11), at + cv::Point(kSymbol, 2), item->colour, cv::FILLED);
        cv::rectangle(m, at + cv::Point(0, -11), at + cv::Point(kSymbol, 2), rgb(120, 120, 120), 1);
        break;
      case LegendItem::Shape::line:
        cv::line(m, at + cv::Point(0, -4), at + cv::Point(kSymbol, -4), item->colour, 2, cv::LINE_AA);
        break;
      case LegendItem::Shape::dot:
        cv::circle(m, mid, 5, item->colour, cv::FILLED, cv::LINE_AA);
        break;
      case LegendItem::Shape::star:
        star(m, mid, 8);
        break;
    }
    text(m, item->name, at + cv::Point(kSymbol + 5, 0), kText);
  }
  return m;
}

// A scale bar in the bottom-left corner of `map` (the map's area of the picture), on a white box.
void draw_scale_bar(cv::Mat& m, const cv::Rect& map, double metres_per_px) {
  const ScaleBar bar = scale_bar_for(map.width, metres_per_px);
  if (bar.pixels < 8) return;
  const std::string label = bar.metres >= 1000 ? fmt(bar.metres / 1000, 0) + " km" : fmt(bar.metres, 0) + " m";
  const int x0 = map.x + 12, y1 = map.y + map.height - 12;
  cv::rectangle(m, cv::Point(x0 - 6, y1 - 26), cv::Point(x0 + bar.pixels + 6, y1 + 5), rgb(255, 255, 255), cv::FILLED);
  // Exactly bar.pixels columns of black.
  cv::rectangle(m, cv::Point(x0, y1 - 4), cv::Point(x0 + bar.pixels - 1, y1), rgb(0, 0, 0), cv::FILLED);
  text(m, label, cv::Point(x0, y1 - 10), 0.45);
}

// An arrow to true north in the top-right corner of `map`; grid north is up, and true north is at
// grid heading -gamma (the CRS's meridian convergence at the map's centre).
void draw_north_arrow(cv::Mat& m, const cv::Rect& map, double gamma_deg) {
  const cv::Point2d c(map.x + map.width - 26, map.y + 34);
  const double a = -gamma_deg * core::kDegToRad;
  const cv::Point2d dir(std::sin(a), -std::cos(a)), side(std::cos(a), std::sin(a));
  cv::circle(m, c, 20, rgb(255, 255, 255), cv::FILLED, cv::LINE_AA);
  cv::circle(m, c, 20, rgb(120, 120, 120), 1, cv::LINE_AA);
  const std::vector<cv::Point> head{c + dir * 16, c - dir * 10 + side * 7, c - dir * 4, c - dir * 10 - side * 7};
  cv::fillPoly(m, std::vector<std::vector<cv::Point>>{head}, rgb(0, 0, 0), cv::LINE_AA);
  text(m, "N", cv::Point(static_cast<int>(c.x) - 6, static_cast<int>(c.y) - 22), 0.5);
}

// The convergence at region pixel (u, v): the angle from grid north to true north, clockwise.
double convergence_at(raster::CacheReader& cache, double u, double v) {
  const auto& grid = cache.grid();
  double gamma = 0;
  (void)cache.metadata().projection().reverse({grid.min_x() + (u + 0.5) * kCellM, grid.max_y() - (v + 0.5) * kCellM},
                                              gamma);
  return gamma;
}

// The map of region pixels [u0, u0 + w) x [v0, v0 + h) at `scale` picture pixels per region
// pixel (nearest when enlarging, averaged when shrinking), read a band of rows at a time, and the
// classes that occur in it. Beyond kMaxMapCells the map is left white.
struct MapLayer {
  cv::Mat image;
  std::vector<LegendItem> legend;
};
constexpr std::int64_t kMaxMapCells = std::int64_t{256} << 20;
MapLayer map_layer(raster::CacheReader& cache, std::int64_t u0, std::int64_t v0, int w, int h, double scale) {
  MapLayer layer;
  const int out_w = std::max(1, static_cast<int>(std::lround(w * scale)));
  const int out_h = std::max(1, static_cast<int>(std::lround(h * scale)));
  layer.image = cv::Mat(out_h, out_w, CV_8UC3, rgb(255, 255, 255));
  if (static_cast<std::int64_t>(w) * h > kMaxMapCells) return layer;
  SeenClasses seen{};
  std::vector<std::uint8_t> classes;
  const int band = 512;
  for (int top = 0; top < h; top += band) {
    const int rows = std::min(band, h - top);
    cache.read_classes(u0, v0 + top, w, rows, classes, /*fill_outside=*/true);
    note_classes(classes, seen);
    Picture colours = map_picture(classes, w, rows);
    const int y0 = static_cast<int>(std::lround(top * scale)), y1 = static_cast<int>(std::lround((top + rows) * scale));
    if (y1 <= y0) continue;
    cv::Mat part;
    cv::resize(to_mat(colours), part, cv::Size(out_w, y1 - y0), 0, 0, scale >= 1 ? cv::INTER_NEAREST : cv::INTER_AREA);
    part.copyTo(layer.image(cv::Rect(0, y0, out_w, y1 - y0)));
  }
  layer.legend = classes_legend(seen);
  return layer;
}

// A figure: its title above, the picture, the legend below.
cv::Mat titled(const std::string& title, const cv::Mat& body, const std::vector<LegendItem>& legend) {
  const cv::Mat strip = legend_strip(legend, std::max(body.cols, 420));
  cv::Mat out(30 + body.rows + strip.rows, std::max(body.cols, strip.cols), CV_8UC3, rgb(255, 255, 255));
  body.copyTo(out(cv::Rect(0, 30, body.cols, body.rows)));
  if (!strip.empty()) strip.copyTo(out(cv::Rect(0, 30 + body.rows, strip.cols, strip.rows)));
  text(out, title, cv::Point(6, 20), 0.5);
  return out;
}

// The map around region-pixel points: 40 m beyond them, at most 1400 picture pixels a side and
// at most 2 per region pixel (0.25 m).
struct RouteMap {
  MapLayer layer;
  MapView view;
};
RouteMap route_map(raster::CacheReader& cache, const std::vector<cv::Point2d>& points) {
  double u0 = 1e18, v0 = 1e18, u1 = -1e18, v1 = -1e18;
  for (const auto& p : points)
    u0 = std::min(u0, p.x), v0 = std::min(v0, p.y), u1 = std::max(u1, p.x), v1 = std::max(v1, p.y);
  const double margin = 40 / kCellM;
  RouteMap map;
  map.view.u0 = static_cast<std::int64_t>(std::floor(u0 - margin));
  map.view.v0 = static_cast<std::int64_t>(std::floor(v0 - margin));
  const int width = static_cast<int>(std::ceil(u1 + margin)) - static_cast<int>(map.view.u0);  // region pixels
  const int height = static_cast<int>(std::ceil(v1 + margin)) - static_cast<int>(map.view.v0);
  map.view.scale = std::min(2.0, 1400.0 / std::max(width, height));
  map.layer = map_layer(cache, map.view.u0, map.view.v0, width, height, map.view.scale);
  return map;
}

// Scale bar and north arrow on a map picture `m` showing `view` (the map fills m).
void decorate(cv::Mat& m, raster::CacheReader& cache, const MapView& view) {
  const cv::Rect all(0, 0, m.cols, m.rows);
  draw_scale_bar(m, all, view.metres_per_px());
  const double u = static_cast<double>(view.u0) + m.cols / view.scale / 2,
               v = static_cast<double>(view.v0) + m.rows / view.scale / 2;
  draw_north_arrow(m, all, convergence_at(cache, u, v));
}

cv::Point2d picture_point(const MapView& view, cv::Point2d region_px) {
  const auto a = view.at(region_px.x, region_px.y);
  return {a[0], a[1]};
}

}  // namespace

void write_picture(const std::filesystem::path& path, const Picture& picture) {
  const auto png = raster::encode_png_rgb8(picture.rgb, picture.width, picture.height);
  core::write_file(path, std::string(png.begin(), png.end()));
}

Picture map_picture(std::span<const std::uint8_t> classes_rgb, int width, int height) {
  return {
      width, height,
      raster::class_colours(classes_rgb.first(static_cast<std::size_t>(width) * static_cast<std::size_t>(height) * 3))};
}

ScaleBar scale_bar_for(int width_px, double metres_per_px) {
  ScaleBar best;
  if (!(metres_per_px > 0) || width_px <= 0) return best;
  const double target = width_px * metres_per_px / 5, most = width_px * metres_per_px / 3;
  double best_miss = std::numeric_limits<double>::max();
  for (int k = -1; k <= 7; ++k) {
    for (const double m : {1.0, 2.0, 5.0}) {
      const double metres = m * std::pow(10.0, k);
      if (metres > most) continue;
      const double miss = std::abs(std::log(metres / target));
      if (miss < best_miss) best_miss = miss, best = {metres, static_cast<int>(std::lround(metres / metres_per_px))};
    }
  }
  return best;
}

std::array<std::uint8_t, 3> error_colour(std::optional<double> error_m) {
  if (!error_m) return {150, 150, 150};
  if (*error_m < 1) return {26, 152, 80};
  if (*error_m < 3) return {145, 207, 96};
  if (*error_m < 5) return {253, 174, 97};
  return {215, 48, 39};
}

Picture plot(const std::vector<Series>& series, const std::string& title, const std::string& x_label,
             const std::string& y_label, double y_max) {
  const int w = 900, h = 520, left = 70, right = 180, top = 40, bottom = 60;
  cv::Mat m(h, w, CV_8UC3, rgb(255, 255, 255));
  double x0 = std::numeric_limits<double>::max(), x1 = -x0, y1 = 0;
  for (const auto& s : series) {
    for (double x : s.x) x0 = std::min(x0, x), x1 = std::max(x1, x);
    for (double y : s.y) y1 = std::max(y1, y);
  }
  if (x0 > x1) x0 = 0, x1 = 1;
  if (x1 == x0) x1 = x0 + 1;
  if (y_max > 0) y1 = y_max;
  if (!(y1 > 0)) y1 = 1;
  auto px = [&](double x, double y) {
    return cv::Point(static_cast<int>(left + (x - x0) / (x1 - x0) * (w - left - right)),
                     static_cast<int>(h - bottom - std::min(y, y1) / y1 * (h - top - bottom)));
  };
  cv::rectangle(m, px(x0, 0), px(x1, y1), rgb(0, 0, 0));
  const double ys = nice_step(y1), xs = nice_step(x1 - x0);
  // Grid lines at whole multiples of the step, counted in integers.
  for (int i = 0; i * ys <= y1 + 1e-9; ++i) {
    const double y = i * ys;
    cv::line(m, px(x0, y), px(x1, y), rgb(225, 225, 225));
    text(m, fmt(y, ys < 1 ? 2 : 0), px(x0, y) + cv::Point(-50, 5), 0.4);
  }
  for (auto i = static_cast<int>(std::ceil(x0 / xs)); i * xs <= x1 + 1e-9; ++i) {
    const double x = i * xs;
    text(m, fmt(x, xs < 1 ? 2 : 0), px(x, 0) + cv::Point(-10, 18), 0.4);
  }
  static const cv::Scalar palette[] = {rgb(31, 119, 180), rgb(255, 127, 14),  rgb(44, 160, 44),
                                       rgb(214, 39, 40),  rgb(148, 103, 189), rgb(140, 86, 75)};
  for (std::size_t k = 0; k < series.size(); ++k) {
    const auto& s = series[k];
    const cv::Scalar colour = palette[k % 6];
    for (std::size_t i = 0; i < s.x.size(); ++i) {
      if (s.points) {
        cv::circle(m, px(s.x[i], s.y[i]), s.x.size() == 1 ? 6 : 2, colour, cv::FILLED,
                   cv::LINE_AA);  // a lone point shows
      } else if (i > 0) {
        cv::line(m, px(s.x[i - 1], s.y[i - 1]), px(s.x[i], s.y[i]), colour, 2, cv::LINE_AA);
      }
    }
    const cv::Point at(w - right + 15, top + 20 + 22 * static_cast<int>(k));
    cv::rectangle(m, at + cv::Point(0, -10), at + cv::Point(14, 2), colour, cv::FILLED);
    text(m, s.label, at + cv::Point(20, 0));
  }
  // The title on the first line, the y axis's label on the second, just above the axis.
  text(m, title, cv::Point(left, 18), 0.55);
  text(m, x_label, cv::Point((w - right) / 2, h - 15));
  text(m, y_label, cv::Point(5, top - 8), 0.4);
  return from_mat(m);
}

std::size_t spread_cells(std::span<const double> marginal, double mass) {
  std::vector<double> sorted(marginal.begin(), marginal.end());
  std::sort(sorted.begin(), sorted.end(), std::greater<>());
  double total = 0;
  for (const double m : sorted) total += m;
  double held = 0;
  std::size_t cells = 0;
  while (cells < sorted.size() && held < mass * total) held += sorted[cells++];
  return std::max<std::size_t>(cells, 1);
}

std::size_t collapse_frame(const std::filesystem::path& beliefs_dir, std::size_t frames,
                           std::span<const io::FramePose> seqloc_poses, double onto_m) {
  const io::KeptBeliefs beliefs(beliefs_dir, frames);
  std::vector<double> ratio(frames, 0.0);  // spread before frame t over spread after it
  auto before = static_cast<double>(spread_cells(beliefs.marginal(0)));
  for (std::size_t t = 1; t < frames; ++t) {
    const auto after = static_cast<double>(spread_cells(beliefs.marginal(t)));
    ratio[t] = before / after;
    before = after;
  }
  auto error = [&](std::size_t t) -> std::optional<double> {
    return t < seqloc_poses.size() ? seqloc_poses[t].position_error_m : std::nullopt;
  };
  // Best: the error falls from beyond onto_m to within it (the belief collapses onto the truth);
  // else it falls and ends within onto_m; else any frame.
  auto tier = [&](std::size_t t) {
    const auto was = error(t - 1), is = error(t);
    if (!was || !is || *is >= *was || *is > onto_m) return 0;
    return *was > onto_m ? 2 : 1;
  };
  int wanted = 0;
  for (std::size_t t = 1; t < frames; ++t) wanted = std::max(wanted, tier(t));
  std::size_t best = 0;
  for (std::size_t t = 1; t < frames; ++t) {
    if (tier(t) == wanted && ratio[t] > ratio[best]) best = t;
  }
  return best;
}

namespace {

using PosesByMode = std::vector<std::pair<std::string, std::vector<io::FramePose>>>;

// What the likelihood figure shows around frame K, as position marginals over the belief window:
// the SeqLoc belief the frame arrives on, the frame's own likelihood and the belief after it.
struct FrameScene {
  int width = 0, height = 0;                                 // the window, cells
  std::int64_t origin_u = 0, origin_v = 0;                   // its corner for frame K
  std::int64_t before_u = 0, before_v = 0;                   // and for frame K - 1
  std::vector<double> frame_mass, belief_mass, before_mass;  // before_mass empty for K = 0
  double entropy = 0;                                        // frame K's normalized entropy
  std::vector<io::FramePose> poses;                          // SeqLoc's poses the titles quote (empty: none)
};

// Where a point falls in region pixels.
cv::Point2d region_pixel(const raster::RegionGrid& grid, const osm::RegionProjection& projection,
                         const osm::GeoPoint& where) {
  const auto g = projection.forward(where);
  return {grid.region_u(g.x_m), grid.region_v(g.y_m)};
}

// The scene from what `localize --beliefs` kept.
FrameScene scene_from_kept(const io::Route& route, const PosesByMode& poses_by_mode, const RenderOptions& options) {
  const std::size_t k = options.frame;
  const io::KeptBeliefs beliefs(options.beliefs_dir, route.frames.size());
  FrameScene scene;
  scene.width = beliefs.width();
  scene.height = beliefs.height();
  scene.belief_mass = beliefs.marginal(k);
  scene.origin_u = beliefs.origin(k)[0];
  scene.origin_v = beliefs.origin(k)[1];
  if (k > 0) {
    scene.before_mass = beliefs.marginal(k - 1);
    scene.before_u = beliefs.origin(k - 1)[0];
    scene.before_v = beliefs.origin(k - 1)[1];
  }
  scene.frame_mass = beliefs.likelihood(k);  // the frame as localize placed it in the window
  // The frame's entropy as given (single's poses), else as SeqLoc raised it (seqloc's).
  for (const auto& [mode, p] : poses_by_mode) {
    if (mode == "seqloc" && p.size() == route.frames.size()) scene.poses = p;
  }
  for (const auto& [mode, p] : poses_by_mode) {
    if (mode == "single" && p.size() == route.frames.size()) scene.entropy = p[k].entropy;
  }
  if (scene.entropy == 0 && !scene.poses.empty()) scene.entropy = scene.poses[k].entropy;
  return scene;
}

// The qualitative figure: before (when K > 0), the frame's own likelihood, after; each panel over
// the map of its window, the frame's truth starred.
Picture likelihood_figure(raster::CacheReader& cache, const io::Route& route, const FrameScene& scene, std::size_t k) {
  const auto& grid = cache.grid();
  const auto projection = cache.metadata().projection();
  const int bw = scene.width, bh = scene.height, factor = bw <= 400 ? 2 : 1;
  SeenClasses seen{};
  auto window_map = [&](std::int64_t at_u, std::int64_t at_v) {
    std::vector<std::uint8_t> classes;
    cache.read_classes(at_u, at_v, bw, bh, classes, /*fill_outside=*/true);
    note_classes(classes, seen);
    Picture base = map_picture(classes, bw, bh);
    return to_mat(base).clone();
  };
  auto panel = [&](const cv::Mat& map, const std::vector<double>& mass, const std::string& title, std::int64_t at_u,
                   std::int64_t at_v, std::size_t index) {
    cv::Mat m = map.clone();
    overlay_mass(m, mass);
    m = upscale(m, factor);
    const MapView view{at_u, at_v, static_cast<double>(factor), 0, 0};
    if (const auto& truth = route.frames[index].truth) {
      star(m, picture_point(view, region_pixel(grid, projection, truth->where)), 11);
    }
    decorate(m, cache, view);
    cv::Mat framed(m.rows + 30, m.cols, CV_8UC3, rgb(255, 255, 255));
    m.copyTo(framed(cv::Rect(0, 30, m.cols, m.rows)));
    text(framed, title, cv::Point(6, 20), 0.5);
    return framed;
  };
  auto belief_title = [&](std::size_t index) {
    std::string title = "SeqLoc belief after frame " + std::to_string(index);
    if (index < scene.poses.size() && scene.poses[index].position_error_m) {
      title += ", error " + fmt(*scene.poses[index].position_error_m, 1) + " m";
    }
    return title;
  };
  const cv::Mat map = window_map(scene.origin_u, scene.origin_v);
  std::vector<cv::Mat> panels;
  if (!scene.before_mass.empty()) {
    const bool moved = scene.before_u != scene.origin_u || scene.before_v != scene.origin_v;  // re-centred for K
    panels.push_back(panel(moved ? window_map(scene.before_u, scene.before_v) : map, scene.before_mass,
                           belief_title(k - 1), scene.before_u, scene.before_v, k - 1));
  }
  panels.push_back(panel(map, scene.frame_mass,
                         "frame " + std::to_string(k) + ": its own likelihood (entropy " + fmt(scene.entropy, 3) + ")",
                         scene.origin_u, scene.origin_v, k));
  panels.push_back(panel(map, scene.belief_mass, belief_title(k), scene.origin_u, scene.origin_v, k));
  int width = 0;
  for (const auto& p : panels) width += p.cols + 10;
  std::vector<LegendItem> legend{{"ground truth", rgb(0, 0, 0), LegendItem::Shape::star},
                                 {"probability (red, opacity from the median to the peak)", rgb(230, 20, 20)}};
  for (const auto& item : classes_legend(seen)) legend.push_back(item);
  const cv::Mat strip = legend_strip(legend, width - 10);
  cv::Mat row(panels.front().rows + strip.rows, width - 10, CV_8UC3, rgb(255, 255, 255));
  int x = 0;
  for (const auto& p : panels) {
    p.copyTo(row(cv::Rect(x, 0, p.cols, p.rows)));
    x += p.cols + 10;
  }
  strip.copyTo(row(cv::Rect(0, panels.front().rows, strip.cols, strip.rows)));
  return from_mat(row);
}

// The route's truth coloured by the normalized entropy of each frame, over the map around it.
Picture entropy_route_figure(raster::CacheReader& cache, const io::Route& route, const std::vector<cv::Point2d>& truth,
                             const std::vector<io::FramePose>& poses) {
  RouteMap map = route_map(cache, truth);
  cv::Mat m = map.layer.image;
  for (std::size_t i = 1; i < truth.size(); ++i) {
    cv::line(m, picture_point(map.view, truth[i - 1]), picture_point(map.view, truth[i]), rgb(60, 60, 60), 1,
             cv::LINE_AA);
  }
  for (std::size_t i = 0; i < truth.size() && i < poses.size(); ++i) {
    cv::circle(m, picture_point(map.view, truth[i]), 5, viridis(poses[i].entropy), cv::FILLED, cv::LINE_AA);
  }
  decorate(m, cache, map.view);
  // Colour bar.
  cv::Mat bar(40, std::max(m.cols, 420), CV_8UC3, rgb(255, 255, 255));
  for (int i = 0; i < 300; ++i) cv::line(bar, cv::Point(60 + i, 8), cv::Point(60 + i, 23), viridis(i / 299.0));
  double lo = 1, hi = 0;
  for (const auto& p : poses) lo = std::min(lo, p.entropy), hi = std::max(hi, p.entropy);
  text(bar, "0", cv::Point(45, 21), 0.4);
  text(bar, "1", cv::Point(365, 21), 0.4);
  text(bar, "range in this route: " + fmt(lo, 3) + " .. " + fmt(hi, 3), cv::Point(60, 36), 0.4);
  cv::Mat body(m.rows + bar.rows, std::max(m.cols, bar.cols), CV_8UC3, rgb(255, 255, 255));
  m.copyTo(body(cv::Rect(0, 0, m.cols, m.rows)));
  bar.copyTo(body(cv::Rect(0, m.rows, bar.cols, bar.rows)));
  return from_mat(
      titled(route.name + ": frames at their ground truth, coloured by normalized entropy of their likelihood", body,
             map.layer.legend));
}

// Position error over time, one line per mode (none when no mode has ground truth).
std::vector<Series> error_series(const PosesByMode& poses_by_mode) {
  std::vector<Series> series;
  for (const auto& [mode, p] : poses_by_mode) {
    Series s{mode, {}, {}, false};
    for (std::size_t i = 0; i < p.size(); ++i) {
      if (!p[i].position_error_m) continue;
      s.x.push_back(static_cast<double>(i));
      s.y.push_back(*p[i].position_error_m);
    }
    if (!s.x.empty()) series.push_back(std::move(s));
  }
  return series;
}

}  // namespace

MapFigure route_overview(raster::CacheReader& cache, const io::Route& route, const std::string& mode,
                         const std::vector<io::FramePose>& poses) {
  const auto& grid = cache.grid();
  const auto projection = cache.metadata().projection();
  std::vector<cv::Point2d> truth, estimates, all;
  for (const auto& f : route.frames) {
    if (f.truth) truth.push_back(region_pixel(grid, projection, f.truth->where));
  }
  for (const auto& p : poses) estimates.push_back(region_pixel(grid, projection, {p.lat_deg, p.lon_deg}));
  all = truth;
  all.insert(all.end(), estimates.begin(), estimates.end());
  if (all.empty()) throw UsageError("render: route '" + route.name + "' has neither ground truth nor poses to draw");
  RouteMap map = route_map(cache, all);
  cv::Mat m = map.layer.image;
  for (std::size_t i = 1; i < truth.size(); ++i) {
    cv::line(m, picture_point(map.view, truth[i - 1]), picture_point(map.view, truth[i]), rgb(0, 0, 0), 2, cv::LINE_AA);
  }
  // The worst drawn last, so that no good estimate hides a bad one.
  std::vector<std::size_t> order(estimates.size());
  for (std::size_t i = 0; i < order.size(); ++i) order[i] = i;
  auto error = [&](std::size_t i) { return poses[i].position_error_m.value_or(-1.0); };
  std::stable_sort(order.begin(), order.end(), [&](std::size_t a, std::size_t b) { return error(a) < error(b); });
  for (const std::size_t i : order) {
    cv::circle(m, picture_point(map.view, estimates[i]), 4, scalar(error_colour(poses[i].position_error_m)), cv::FILLED,
               cv::LINE_AA);
  }
  decorate(m, cache, map.view);

  std::string title = route.name + ": " + mode + " estimates coloured by position error, ground truth in black";
  if (const io::Metrics metrics = io::compute_metrics(poses); metrics.frames > 0) {
    title += " (R@5m " + fmt(metrics.position_recall[2], 1) + " %)";
  }
  std::vector<LegendItem> legend{{"ground truth", rgb(0, 0, 0), LegendItem::Shape::line},
                                 {"error < 1 m", scalar(error_colour(0.0)), LegendItem::Shape::dot},
                                 {"< 3 m", scalar(error_colour(1.0)), LegendItem::Shape::dot},
                                 {"< 5 m", scalar(error_colour(3.0)), LegendItem::Shape::dot},
                                 {">= 5 m", scalar(error_colour(5.0)), LegendItem::Shape::dot}};
  legend.insert(legend.end(), map.layer.legend.begin(), map.layer.legend.end());
  MapFigure figure;
  figure.picture = from_mat(titled(title, m, legend));
  figure.view = map.view;
  figure.view.top = 30;
  return figure;
}

std::vector<std::filesystem::path> render_route(raster::CacheReader& cache, const io::Route& route,
                                                const PosesByMode& poses_by_mode, const RenderOptions& options,
                                                const std::filesystem::path& out_dir) {
  if (options.frame >= route.frames.size()) {
    throw UsageError("render: frame " + std::to_string(options.frame) + " of route '" + route.name + "', which has " +
                     std::to_string(route.frames.size()) + " frames");
  }
  std::filesystem::create_directories(out_dir);
  std::vector<std::filesystem::path> written;

  // 1. The SeqLoc belief before and after the frame and the frame's own likelihood, from what
  // localize kept (beliefs.npy, likelihoods.npy).
  if (options.beliefs_dir.empty() || !std::filesystem::exists(options.beliefs_dir / "beliefs.npy")) {
    throw UsageError("render: the likelihood figure draws what seqloc localize --beliefs kept, and " +
                     (options.beliefs_dir.empty() ? std::string("no run folder was given")
                                                  : (options.beliefs_dir / "beliefs.npy").string() + " is missing"));
  }
  const FrameScene scene = scene_from_kept(route, poses_by_mode, options);
  written.push_back(out_dir / ("likelihood_" + std::to_string(options.frame) + ".png"));
  write_picture(written.back(), likelihood_figure(cache, route, scene, options.frame));

  // 2. The route coloured by the normalized entropy of each frame (SeqLoc's run, else any).
  const std::pair<std::string, std::vector<io::FramePose>>* chosen = nullptr;
  for (const auto& mode_poses : poses_by_mode) {
    if (mode_poses.first == "seqloc" || !chosen) chosen = &mode_poses;
  }
  const std::vector<io::FramePose>* poses = chosen ? &chosen->second : nullptr;
  const auto projection = cache.metadata().projection();
  std::vector<cv::Point2d> truth;  // region pixels
  for (const auto& f : route.frames) {
    if (f.truth) truth.push_back(region_pixel(cache.grid(), projection, f.truth->where));
  }
  if (poses && !truth.empty() && poses->size() == route.frames.size()) {
    written.push_back(out_dir / "entropy_route.png");
    write_picture(written.back(), entropy_route_figure(cache, route, truth, *poses));
  }

  // 3. The whole route: SeqLoc's estimates (else any mode's) over the map, coloured by error.
  if (poses && poses->size() == route.frames.size()) {
    written.push_back(out_dir / "overview.png");
    write_picture(written.back(), route_overview(cache, route, chosen->first, *poses).picture);
  }

  // 4. Position error over time, one line per mode.
  if (const auto series = error_series(poses_by_mode); !series.empty()) {
    written.push_back(out_dir / "error_over_time.png");
    write_picture(written.back(),
                  plot(series, route.name + ": position error per frame (clipped at 50 m)", "frame", "error (m)", 50));
  }
  return written;
}

}  // namespace seqloc::render
