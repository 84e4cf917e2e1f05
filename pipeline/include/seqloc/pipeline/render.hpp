#pragma once
// Pictures (docs/render.md): the paper's qualitative figure (a frame's own likelihood and the
// SeqLoc belief, marginalized over heading, in red over the rendered map, the ground truth as a
// star), a route coloured by normalized entropy, error over time, and the scatter of error
// against entropy. PNG files, written through a temporary name.

#include <cstdint>
#include <filesystem>
#include <span>
#include <string>
#include <vector>

#include "seqloc/pipeline/localize.hpp"
#include "seqloc/pipeline/route.hpp"
#include "seqloc/raster/cache.hpp"

namespace seqloc::pipeline {

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

struct RenderOptions {
  std::size_t frame = 0;  ///< the frame of the likelihood figure
  LocalizeOptions localize;
  /// A localize output folder of the route's seqloc mode (OUT/<route>/seqloc): when it holds
  /// beliefs.npy (localize --beliefs), the likelihood figure draws the beliefs kept there and
  /// scores the one frame, instead of running the filter up to the frame.
  std::filesystem::path beliefs_dir;
};

/// Cells of the smallest set holding `mass` of a (non-negative) belief marginal: the area the
/// belief is spread over, whatever its shape.
[[nodiscard]] std::size_t spread_cells(std::span<const double> marginal, double mass = 0.9);

/// The frame (after the first) on which the belief localize kept in `beliefs_dir` (beliefs.npy,
/// beliefs.csv of `localize --beliefs`) collapses most: the largest ratio of spread_cells before
/// the frame to spread_cells after it. Throws DataError naming the file when the beliefs are
/// missing or are not the route's (`frames` frames).
[[nodiscard]] std::size_t collapse_frame(const std::filesystem::path& beliefs_dir, std::size_t frames);

/// Writes likelihood_FRAME.png, entropy_route.png and error_over_time.png for `route` into
/// `out_dir` (created). `poses_by_mode` are localize's results for the same route (any modes;
/// "seqloc" gives the entropy colours); the likelihood figure runs the filter itself up to the
/// frame unless options.beliefs_dir has what localize kept. Returns the files written.
std::vector<std::filesystem::path> render_route(raster::CacheReader& cache, const Route& route,
                                                const std::vector<std::pair<std::string, std::vector<FramePose>>>& poses_by_mode,
                                                const RenderOptions& options, const std::filesystem::path& out_dir);

}  // namespace seqloc::pipeline
