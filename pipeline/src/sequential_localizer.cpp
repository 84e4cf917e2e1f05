#include "seqloc/pipeline/sequential_localizer.hpp"

namespace seqloc::pipeline {
namespace {

filter::FilterConfig mode_config(const filter::FilterConfig& config, bool online) {
  filter::FilterConfig c = config;
  if (online) c.etu = c.mgr = c.pas = c.self_calibrate = false;
  return c;
}

}  // namespace

SequentialLocalizer::SequentialLocalizer(raster::CacheReader& cache, const filter::FilterConfig& config, bool online,
                                         double recentre_margin)
    : config_(mode_config(config, online)),
      recentre_margin_(recentre_margin),
      window_(cache, config_.width, config_.height) {}

FrameEstimate SequentialLocalizer::step(const filter::PreparedFrame& frame, const GridCrop& crop,
                                        const filter::Odometry& odometry, const std::optional<GridFix>& gps) {
  if (!filter_) {
    // The first frame: centred on its GPS fix when it has one (the fix's Gaussian is the prior),
    // else on its crop with a uniform prior.
    filter_.emplace(config_);
    window_.centre_on(gps ? gps->x_m : crop.x, gps ? gps->y_m : crop.y);
    if (gps) {
      filter_->reset_gaussian(window_.u_of(gps->x_m), window_.v_of(gps->y_m), gps->sigma_m);
    } else {
      filter_->reset_uniform();
    }
  }
  // A crop far from the window (the estimate wandered off while the frames' evidence stayed
  // around the GPS-like crops) brings the window to it: evidence outside the window is lost.
  keep_in_window(window_.u_of(crop.x), window_.v_of(crop.y));
  std::optional<filter::GpsFix> fix;
  if (config_.gps_prior && gps) fix = filter::GpsFix{window_.u_of(gps->x_m), window_.v_of(gps->y_m), gps->sigma_m};
  const float* road = config_.mgr ? window_.road_distance_m() : nullptr;
  const filter::FrameResult r = filter_->step(frame, window_.crop_pose(crop), odometry, road, fix ? &*fix : nullptr);
  FrameEstimate e;
  e.x_m = window_.x_of(r.pose.u);
  e.y_m = window_.y_of(r.pose.v);
  e.grid_heading_deg = r.pose.heading_deg;
  e.entropy = r.frame_entropy;
  e.etu_weight = r.etu_weight;
  e.volume_power = r.volume_power;
  e.relocalized = r.relocalized;
  // Keep the window on the vehicle.
  keep_in_window(r.pose.u, r.pose.v);
  return e;
}

// Re-centres the window by whole cells on window position (u, v) when it lies within the margin
// of an edge (or outside).
void SequentialLocalizer::keep_in_window(double u, double v) {
  const auto shift = window_.recentre_shift(u, v, recentre_margin_);
  if (!shift) return;
  filter_->recentre((*shift)[0], (*shift)[1]);
  window_.shift((*shift)[0], (*shift)[1]);
  ++recentres_;
}

}  // namespace seqloc::pipeline
