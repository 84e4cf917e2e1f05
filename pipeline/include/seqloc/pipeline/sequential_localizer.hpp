#pragma once
// The sequential filter (conventions.md section 6) in a window that follows the vehicle over a
// region, one frame at a time: what `seqloc localize` runs for its online and seqloc modes
// (modes/sequential.cpp drives it along a route), and what the Python module's Localizer wraps
// for a loop that brings its own volumes. With a lag L it also smooths: frame t - L's pose given
// the frames up to t (fixed-lag smoothing, docs/localize.md).

#include <array>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <functional>
#include <memory>
#include <optional>
#include <utility>
#include <vector>

#include "seqloc/filter/seqloc_filter.hpp"
#include "seqloc/pipeline/backward_pass.hpp"
#include "seqloc/pipeline/forward_filter.hpp"
#include "seqloc/pipeline/modes.hpp"
#include "seqloc/pipeline/region_window.hpp"

namespace seqloc::pipeline {

/// A GPS fix in region grid metres.
struct GridFix {
  double x_m = 0, y_m = 0, sigma_m = 10;
};

/// Frame `f`'s GPS prior in the grid of `projection`'s region; nothing when it has none.
[[nodiscard]] std::optional<GridFix> frame_gps_fix(const io::RouteFrame& f, const osm::RegionProjection& projection);

class SequentialLocalizer {
 public:
  /// `online`: the filter with ETU, MGR, PAS and self-calibration off (naive fusion); else as
  /// `config` says.
  /// The window re-centres on the vehicle when it comes within `recentre_margin` (a fraction of
  /// its size) of an edge.
  /// `lag` L > 0: fixed-lag smoothing; the localizer keeps the last L + 1 frames and forward
  /// beliefs (L + 1 windows of memory) and after frame t runs the backward filter over frames
  /// t .. t - L + 1 (L backward steps a frame).
  /// `device`: where the forward filter runs (the backward filter of a lag runs on the CPU).
  SequentialLocalizer(raster::CacheReader& cache, const filter::FilterConfig& config, bool online,
                      double recentre_margin, int lag = 0, Device device = Device::cpu);

  /// One frame: its prepared volume, its crop in region grid metres, the odometry since the
  /// previous frame, and a GPS fix if there is one. The first frame places the window on the fix
  /// (whose Gaussian is then the prior) or on the crop (uniform prior). Returns the frame's
  /// filtered estimate (given the frames up to it).
  FrameEstimate step(std::shared_ptr<const filter::PreparedFrame> frame, const GridCrop& crop,
                     const filter::Odometry& odometry, const std::optional<GridFix>& gps);
  /// The same for a frame the caller keeps (copied when a lag needs it later).
  FrameEstimate step(const filter::PreparedFrame& frame, const GridCrop& crop, const filter::Odometry& odometry,
                     const std::optional<GridFix>& gps);

  /// The estimates that became final and were not taken yet, in frame order, with their frame's
  /// index (0: the first frame stepped). Without a lag, each frame's filtered estimate as soon as
  /// it is stepped; with a lag L, after frame t, frame t - L's smoothed estimate given the frames
  /// up to t. Each estimate is in the grid of the region its frame was stepped in.
  [[nodiscard]] std::vector<std::pair<std::size_t, FrameEstimate>> take_final();
  /// The route ends: the frames still waiting for their lag get their smoothed estimates given
  /// every frame (take_final hands them out).
  void finish();
  /// The route crosses into another region: the belief is resampled onto a window of the same
  /// size in `next`'s grid centred where the old one was (nearest cell; headings turned by the
  /// difference of the two CRSs' meridian convergence, interpolated between bins). The next step's
  /// crop and estimate are in `next`'s grid. Frames waiting for their lag keep waiting: the
  /// backward filter carries its belief back across the seam into their region.
  void hand_over(raster::CacheReader& next);

  /// A frame the early replay filtered again (FilterConfig::self_calibration_replay_frames): its
  /// index, its record with the weighting it went in at the second time, and, where
  /// want_replayed_alphas asked for it, the forward belief after it.
  struct Rewrite {
    std::size_t index;
    StepRecord record;
    std::optional<filter::BeliefVolume> alpha;
  };
  /// The frames replayed since the last call, oldest first (a caller keeping records of its own,
  /// as smooth does, takes them after each step). Their poses, handed out before, are not changed.
  [[nodiscard]] std::vector<Rewrite> take_rewritten();
  /// Which replayed frames' forward beliefs take_rewritten hands out (none unless asked).
  void want_replayed_alphas(std::function<bool(std::size_t)> wanted) { alphas_wanted_ = std::move(wanted); }

  /// Estimates without their uncertainty (for a caller that makes its own, as smooth does from
  /// the smoothed posterior): saves a pass over the belief per frame.
  void without_uncertainty() { uncertainty_ = false; }

  [[nodiscard]] const filter::FilterConfig& config() const { return config_; }
  [[nodiscard]] int lag() const { return lag_; }
  [[nodiscard]] const RegionWindow& window() const { return window_; }
  /// The filter, once the first frame started it.
  [[nodiscard]] const ForwardFilter* filter() const { return filter_ ? &*filter_ : nullptr; }
  /// What the last step did (for a second pass over the route).
  [[nodiscard]] const StepRecord& last_step() const { return last_; }
  /// How often the window moved.
  [[nodiscard]] int recentres() const { return recentres_; }

 private:
  struct Waiting {
    std::size_t index;
    raster::CacheReader* region;  ///< the region the frame was stepped in
    StepRecord record;
    std::shared_ptr<const filter::PreparedFrame> frame;
    filter::BeliefVolume alpha;
  };
  /// The route's first frames, kept for the early replay: the belief and window origin the route
  /// started from, and each frame's record and volume.
  struct Early {
    filter::BeliefVolume prior;
    std::array<std::int64_t, 2> origin{};
    std::vector<StepRecord> records;
    std::vector<std::shared_ptr<const filter::PreparedFrame>> frames;
    int replays = 0;
  };
  void keep_in_window(double u, double v);
  /// Keeps the step just taken (`record`, `frame`, its result `r`) and, when StepDecisions says
  /// so, filters every kept frame again at r's power: returns the newest frame's result then.
  filter::FrameResult replay_early(std::shared_ptr<const filter::PreparedFrame> frame, const StepRecord& record,
                                   const filter::FrameResult& r);
  /// Frames [from, waiting_.size()) of waiting_ smoothed by one backward pass from the last.
  void smooth_waiting(std::size_t from, std::size_t to_emit);

  filter::FilterConfig config_;
  double recentre_margin_;
  int lag_;
  Device device_;
  bool uncertainty_ = true;
  RegionWindow window_;
  std::optional<ForwardFilter> filter_;
  int recentres_ = 0;
  std::size_t stepped_ = 0;
  StepRecord last_;
  std::deque<Waiting> waiting_;
  std::optional<BackwardPass> backward_;
  std::vector<std::pair<std::size_t, FrameEstimate>> final_;
  std::optional<Early> early_;
  std::vector<Rewrite> rewritten_;
  std::function<bool(std::size_t)> alphas_wanted_;
};

}  // namespace seqloc::pipeline
