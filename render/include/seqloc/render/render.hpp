#pragma once
// Pictures (docs/render.md): a route's overview (the estimates over the map, coloured by error),
// the paper's qualitative figure (a frame's own likelihood and the SeqLoc belief, marginalized
// over heading, in red over the rendered map, the ground truth as a star), a route coloured by
// normalized entropy, and error over time; each map with a scale bar, north arrow and legend. PNG
// files, written through a temporary name.

#include <array>
#include <cstdint>
#include <filesystem>
#include <optional>
#include <span>
#include <string>
#include <vector>

#include "seqloc/io/results.hpp"
#include "seqloc/io/route.hpp"
#include "seqloc/raster/cache.hpp"

namespace seqloc::render {

/// An 8-bit RGB picture, row-major.
struct Picture {
  int width = 0, height = 0;
  std::vector<std::uint8_t> rgb;
};

void write_picture(const std::filesystem::path& path, const Picture& picture);

/// The class raster in colours (background white; areas, then ways, then nodes drawn on top).
[[nodiscard]] Picture map_picture(std::span<const std::uint8_t> classes_rgb, int width, int height);

/// One series of a plot.
struct Series {
  std::string label;
  std::vector<double> x, y;
  bool points = false;  ///< scatter points instead of a line
};
/// A plot with axes, ticks and a legend; y is clipped to [0, y_max] when y_max > 0.
[[nodiscard]] Picture plot(const std::vector<Series>& series, const std::string& title, const std::string& x_label,
                           const std::string& y_label, double y_max = 0);

/// Where region pixels fall in a map picture: region pixel (u0, v0)'s top-left corner at picture
/// (left, top), `scale` picture pixels per region pixel (0.5 m).
struct MapView {
  std::int64_t u0 = 0, v0 = 0;
  double scale = 1;
  int left = 0, top = 0;
  /// The picture position of a point at region pixel coordinates (u, v) (pixel centres integral).
  [[nodiscard]] std::array<double, 2> at(double u, double v) const {
    return {left + (u - static_cast<double>(u0) + 0.5) * scale, top + (v - static_cast<double>(v0) + 0.5) * scale};
  }
  [[nodiscard]] double metres_per_px() const { return 0.5 / scale; }
};

/// A scale bar: a round length (1, 2 or 5 x 10^k m) as near as it can be to a fifth of a map
/// picture `width_px` wide, never wider than a third, and its length in picture pixels.
struct ScaleBar {
  double metres = 0;
  int pixels = 0;
};
[[nodiscard]] ScaleBar scale_bar_for(int width_px, double metres_per_px);

/// The colour (RGB) of a position error in the route overview, by the recall thresholds as
/// compute_metrics counts them (error < t): under 1 m, 3 m, 5 m, and 5 m or more (no ground
/// truth: grey).
[[nodiscard]] std::array<std::uint8_t, 3> error_colour(std::optional<double> error_m);

/// One route's overview: the map around it, the ground truth as a black line, and the estimates
/// of `poses` (one mode's, of the route's frames) as dots coloured by error_colour, with a scale
/// bar, a north arrow and a legend. `view` places region pixels in the picture.
struct MapFigure {
  Picture picture;
  MapView view;
};
[[nodiscard]] MapFigure route_overview(raster::CacheReader& cache, const io::Route& route, const std::string& mode,
                                       const std::vector<io::FramePose>& poses);

struct RenderOptions {
  std::size_t frame = 0;  ///< the frame of the likelihood figure
  /// A localize output folder of the route's seqloc mode (OUT/<route>/seqloc) holding what
  /// `seqloc localize --beliefs` kept (beliefs.npy, beliefs.csv, likelihoods.npy): the likelihood
  /// figure draws the beliefs and the frame's own likelihood from there.
  std::filesystem::path beliefs_dir;
};

/// Cells of the smallest set holding `mass` of a (non-negative) belief marginal: the area the
/// belief is spread over, whatever its shape.
[[nodiscard]] std::size_t spread_cells(std::span<const double> marginal, double mass = 0.9);

/// The frame (after the first) on which the belief localize kept in `beliefs_dir` (beliefs.npy,
/// beliefs.csv of `localize --beliefs`) collapses onto the truth: the largest ratio of
/// spread_cells before the frame to spread_cells after it, among the frames where SeqLoc's error
/// (`seqloc_poses`, the same run's poses) falls from beyond `onto_m` metres to within it; where
/// no frame's does, among those where it falls and ends within onto_m; else among all frames
/// (and without errors). Throws DataError naming the file when the
/// beliefs are missing or are not the route's (`frames` frames).
[[nodiscard]] std::size_t collapse_frame(const std::filesystem::path& beliefs_dir, std::size_t frames,
                                         std::span<const io::FramePose> seqloc_poses = {}, double onto_m = 5.0);

/// Writes overview.png, likelihood_FRAME.png, entropy_route.png and error_over_time.png for `route` into
/// `out_dir` (created). `poses_by_mode` are localize's results for the same route (any modes;
/// "seqloc" gives the entropy colours); the likelihood figure draws what localize kept in
/// options.beliefs_dir (UsageError when it holds no beliefs.npy; DataError naming a file that is
/// missing or not the route's). Returns the files written.
std::vector<std::filesystem::path> render_route(
    raster::CacheReader& cache, const io::Route& route,
    const std::vector<std::pair<std::string, std::vector<io::FramePose>>>& poses_by_mode, const RenderOptions& options,
    const std::filesystem::path& out_dir);

}  // namespace seqloc::render
