#pragma once
// The sequential filter (conventions.md section 6) in a window that follows the vehicle over a
// region, one frame at a time: what `seqloc localize` runs for its online and seqloc modes
// (modes/sequential.cpp drives it along a route), and what the Python module's Localizer wraps
// for a loop that brings its own volumes.

#include <optional>

#include "seqloc/filter/seqloc_filter.hpp"
#include "seqloc/pipeline/modes.hpp"
#include "seqloc/pipeline/region_window.hpp"

namespace seqloc::pipeline {

/// A GPS fix in region grid metres.
struct GridFix {
  double x_m = 0, y_m = 0, sigma_m = 10;
};

class SequentialLocalizer {
 public:
  /// `online`: the filter with ETU, MGR, PAS and self-calibration off (naive fusion); else as
  /// `config` says.
  /// The window re-centres on the vehicle when it comes within `recentre_margin` (a fraction of
  /// its size) of an edge.
  SequentialLocalizer(raster::CacheReader& cache, const filter::FilterConfig& config, bool online,
                      double recentre_margin);

  /// One frame: its prepared volume, its crop in region grid metres, the odometry since the
  /// previous frame, and a GPS fix if there is one. The first frame places the window on the fix
  /// (whose Gaussian is then the prior) or on the crop (uniform prior).
  [[nodiscard]] FrameEstimate step(const filter::PreparedFrame& frame, const GridCrop& crop,
                                   const filter::Odometry& odometry, const std::optional<GridFix>& gps);

  [[nodiscard]] const filter::FilterConfig& config() const { return config_; }
  [[nodiscard]] const RegionWindow& window() const { return window_; }
  /// The filter, once the first frame started it.
  [[nodiscard]] const filter::SeqLocFilter* filter() const { return filter_ ? &*filter_ : nullptr; }
  /// How often the window moved.
  [[nodiscard]] int recentres() const { return recentres_; }

 private:
  void keep_in_window(double u, double v);

  filter::FilterConfig config_;
  double recentre_margin_;
  RegionWindow window_;
  std::optional<filter::SeqLocFilter> filter_;
  int recentres_ = 0;
};

}  // namespace seqloc::pipeline
