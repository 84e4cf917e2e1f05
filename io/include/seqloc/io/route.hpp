#pragma once
// A route directory (conventions.md section 5): route.json and frames.csv, read and checked
// completely before any work starts, so that a bad row stops the run before an output exists.

#include <cstddef>
#include <filesystem>
#include <functional>
#include <optional>
#include <string>
#include <vector>

#include "seqloc/core/error.hpp"
#include "seqloc/core/units.hpp"
#include "seqloc/core/volume.hpp"
#include "seqloc/osm/projection.hpp"

namespace seqloc::io {

struct GpsPrior {
  osm::GeoPoint where;
  double sigma_m = 0;
};

struct GroundTruth {
  osm::GeoPoint where;
  std::optional<double> heading_deg;  ///< compass, clockwise from true north
};

struct RouteFrame {
  int line = 0;  ///< line in frames.csv (the header is line 1)
  std::string frame;
  double timestamp_s = 0;
  std::filesystem::path volume;  ///< absolute; empty when the frame has an observation
  std::filesystem::path observation;
  std::optional<osm::GeoPoint> crop_geo;    ///< crop centre as lat/lon (tangent-plane, true north)
  std::optional<osm::GridPoint> crop_grid;  ///< or in region-grid coordinates (grid north)
  core::Odometry odometry;                  ///< from the previous frame (0 on the first)
  std::optional<GpsPrior> gps;
  std::optional<GroundTruth> truth;
};

/// The axis order of a route's volumes: (H, W, N), OrienterNet's log_probs without the batch
/// axis, or (N, H, W), headings first, as a network's scores often come.
enum class VolumeLayout { hwn, nhw };

struct Route {
  std::filesystem::path dir;
  std::string name;
  core::VolumeValues volume_kind = core::VolumeValues::log_prob;
  double cell_m = core::kCellM;
  VolumeLayout layout = VolumeLayout::hwn;
  bool layout_declared = false;  ///< route.json names the layout (else HWN, with a check of each shape)
  /// route.json's "simulated" object as JSON text (the provenance `seqloc simulate` records), or
  /// empty; carried through, read by no one.
  std::string simulated_json;
  std::vector<RouteFrame> frames;
};

class NpyVolume;

/// Throws DataError naming the file and its frames.csv line when `route` declares no layout and
/// frame `f`'s volume `npy` reads better as (N, H, W), headings first and a square crop last:
/// read as (H, W, N) it would run to the end and give nonsense.
void check_volume_layout(const Route& route, const RouteFrame& f, const NpyVolume& npy);

/// Frame `f`'s volume `npy` as the filter takes it, (H, W, N): the mapped file itself, or for an
/// NHW route its values transposed into `buffer`. Checks the layout (check_volume_layout).
[[nodiscard]] core::FrameVolume frame_volume(const Route& route, const RouteFrame& f, const NpyVolume& npy,
                                             std::vector<unsigned char>& buffer);

/// Plausibility limits of the odometry between consecutive frames.
struct RouteLimits {
  double max_step_m = 200.0;    ///< one increment's translation
  double max_speed_mps = 70.0;  ///< translation over the time between frames (250 km/h)
  double max_yaw_deg = 120.0;   ///< one increment's heading change

  void validate() const;  ///< throws UsageError naming the bad field
};

/// Reads and checks a route directory. Throws DataError: "DIR/route.json: ..." or
/// "DIR/frames.csv:LINE: ..." naming what is wrong.
[[nodiscard]] Route read_route(const std::filesystem::path& dir, const RouteLimits& limits = {});

/// Which of a run's routes one process takes (`seqloc localize --shard I/N`): the route at place
/// k of the sorted folders belongs to shard k mod N.
struct Shard {
  int index = 0;
  int count = 1;
};

/// The routes of a run: every folder of `dirs` read and checked with `limits` (read_route), in
/// sorted order, a name that two folders share getting "-K" (K its 1-based place) on the second.
/// Those of `shard` are returned; the others are only passed to `check_other` (when given), so
/// that a shard's route names and errors do not depend on which shard runs. Throws DataError
/// naming the file and line.
[[nodiscard]] std::vector<Route> read_routes(std::vector<std::filesystem::path> dirs, const RouteLimits& limits,
                                             const Shard& shard = {},
                                             const std::function<void(const Route&)>& check_other = {});

/// The frames of all `routes`.
[[nodiscard]] std::size_t frame_count(const std::vector<Route>& routes);

/// Writes `route` as route.json and frames.csv into `dir` (created), the reverse of read_route:
/// numbers in their shortest form that reads back to the same double, volume and observation
/// paths relative to `dir` when they lie under it, and only the columns some frame uses (all
/// frames' crops as lat/lon when the first has one, else in grid metres). Throws DataError when a
/// file cannot be written.
void write_route(const Route& route, const std::filesystem::path& dir);

}  // namespace seqloc::io
