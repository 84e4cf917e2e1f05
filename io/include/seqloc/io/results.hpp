#pragma once
// What localizing a route gives, in the conventions' terms (conventions.md sections 1 and 7): a
// pose per frame with its errors against the ground truth, a result per route and mode, and the
// metrics over them. The run folder (run_folder.hpp) writes and reads them.

#include <array>
#include <cstdint>
#include <optional>
#include <span>
#include <string>
#include <string_view>
#include <vector>

namespace seqloc::io {

/// The ways of localizing a route (docs/localize.md): one frame alone, the frames around each
/// (offline), the naive online filter, SeqLoc, and SeqLoc smoothed over the whole route.
enum class Mode { seqloc, online, single, offline, smooth };
/// Every mode, in the order the recall table lists them.
inline constexpr std::array<Mode, 5> kModes{Mode::single, Mode::offline, Mode::online, Mode::seqloc, Mode::smooth};
/// "seqloc", "online", "single", "offline" or "smooth": the mode's folder and column name.
[[nodiscard]] const char* mode_name(Mode mode);
/// The mode of that name; nothing for another text.
[[nodiscard]] std::optional<Mode> parse_mode(std::string_view name);

struct FramePose {
  std::string frame;
  double timestamp_s = 0;
  double x_m = 0, y_m = 0;  ///< region CRS
  double lat_deg = 0, lon_deg = 0;
  double compass_heading_deg = 0;  ///< clockwise from true north
  double grid_heading_deg = 0;     ///< clockwise from grid north (for files in the region CRS)
  double entropy = 0;              ///< the frame volume's normalized entropy
  double etu_weight = 1;
  /// The power self-calibration raised the frame's volume to (seqloc mode; 1 in the others and
  /// with --no-self-calibrate): for volumes sharpened as p^k it tends to 1 / k.
  double volume_power = 1;
  bool relocalized = false;
  std::optional<double> position_error_m, heading_error_deg, lateral_error_m, longitudinal_error_m;
  /// The ground truth of the frame, when the route has it, in the same forms as the estimate.
  struct Truth {
    double x_m = 0, y_m = 0, lat_deg = 0, lon_deg = 0;
    std::optional<double> grid_heading_deg;     ///< clockwise from grid north
    std::optional<double> compass_heading_deg;  ///< clockwise from true north
  };
  std::optional<Truth> truth;
  /// The region (cache file stem) whose CRS x_m, y_m and the errors are in.
  std::string region;
  /// How far to trust the pose, from the belief it came from (uncertainty/pose_uncertainty.hpp): the modes
  /// with a belief (online, seqloc, smooth) give it, single and offline do not.
  struct Uncertainty {
    double cov_xx_m2 = 0, cov_xy_m2 = 0,
           cov_yy_m2 = 0;  ///< position covariance along the region's x (east) and y (north)
    double heading_sd_deg = 0;
    double mass_within_5m = 0;
    double second_mode_share = 0;
    bool multimodal = false;
  };
  std::optional<Uncertainty> uncertainty;
};

struct RouteResult {
  std::string route;
  Mode mode = Mode::seqloc;
  std::vector<FramePose> poses;
  int recentres = 0;         ///< how often the window moved
  int region_crossings = 0;  ///< how often the route crossed into another region
  int lag = 0;               ///< online and seqloc: the fixed lag the poses were smoothed with (LocalizeOptions::lag)
  /// Where the time went (seconds). Reading and preparing the next frame's volume overlaps the
  /// filter's step on the current one; `wait_seconds` is what the filter waited for it.
  double prepare_seconds = 0;
  double filter_seconds = 0;
  double wait_seconds = 0;
  /// With LocalizeOptions::keep_beliefs (online and seqloc): after each frame, the position marginal of
  /// the belief, (frames, belief_height, belief_width) row-major, and the region pixel of each
  /// frame's window cell (0, 0).
  /// `likelihoods`: each frame's own likelihood over position in the same window, (frames,
  /// belief_height, belief_width) (its volume summed over headings, each cell's mass at the window
  /// cell its centre falls in), what the likelihood figure draws.
  int belief_width = 0, belief_height = 0;
  std::vector<float> beliefs, likelihoods;
  std::vector<std::array<std::int64_t, 2>> belief_origins;
};

/// conventions.md section 7, over every frame with ground truth.
struct Metrics {
  std::size_t frames = 0;          ///< frames with ground truth
  double position_recall[3] = {};  ///< % of frames within 1, 3, 5 m
  double heading_recall[3] = {};   ///< % within 1, 3, 5 degrees (frames with a true heading)
  double mean_position_error_m = 0, median_position_error_m = 0;
  double mean_heading_error_deg = 0, median_heading_error_deg = 0;
  double mean_abs_lateral_m = 0, mean_abs_longitudinal_m = 0;
};
[[nodiscard]] Metrics compute_metrics(std::span<const FramePose> poses);

/// How honest the poses' uncertainty is, over the frames with both ground truth and an
/// uncertainty (docs/route-format.md, "Uncertainty"): the share whose truth lies inside the
/// reported 95 % position ellipse, and the reported mass within 5 m against how often the truth
/// is within 5 m, binned by the reported value (tenths) into a reliability table and its expected
/// calibration error (the bins' |reported - actual| weighted by their frames).
struct UncertaintyCalibration {
  std::size_t frames = 0;
  double coverage_95_pct = 0;
  double mass_5m_ece_pts = 0;
  struct Bin {
    std::size_t frames = 0;
    double reported_pct = 0, actual_pct = 0;  ///< mean reported mass within 5 m; share within 5 m
  };
  std::array<Bin, 10> reliability{};
};
[[nodiscard]] std::optional<UncertaintyCalibration> uncertainty_calibration(std::span<const FramePose> poses);

}  // namespace seqloc::io
