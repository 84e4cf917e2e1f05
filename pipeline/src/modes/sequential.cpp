// online and seqloc: the sequential filter (conventions.md section 6) in a window that follows the
// vehicle. online is the same filter with ETU, MGR and PAS off (naive fusion).
#include <optional>

#include "factories.hpp"
#include "seqloc/pipeline/region_window.hpp"

namespace seqloc::pipeline::modes {
namespace {

filter::FilterConfig mode_config(const filter::FilterConfig& config, bool online) {
  filter::FilterConfig c = config;
  if (online) c.etu = c.mgr = c.pas = false;
  return c;
}

class SequentialMode final : public LocalizationMode {
 public:
  SequentialMode(const RouteContext& context, bool online)
      : LocalizationMode(context),
        config_(mode_config(context.options.filter, online)),
        window_(context.cache, config_.width, config_.height) {}

  FrameEstimate estimate(std::size_t i, const GridCrop& crop, FramePrefetcher& frames) override {
    const RouteFrame& f = context_.route.frames[i];
    const auto& projection = context_.cache.metadata().projection();
    const filter::PreparedFrame& frame = frames.get(i);
    if (!filter_) start(f, crop);
    // A crop far from the window (the estimate wandered off while the frames' evidence stayed
    // around the GPS-like crops) brings the window to it: evidence outside the window is lost.
    keep_in_window(window_.u_of(crop.x), window_.v_of(crop.y));
    std::optional<filter::GpsFix> fix;
    if (config_.gps_prior && f.gps) {
      const auto g = projection.forward(f.gps->where);
      fix = filter::GpsFix{window_.u_of(g.x_m), window_.v_of(g.y_m), f.gps->sigma_m};
    }
    const float* road = config_.mgr ? window_.road_distance_m() : nullptr;
    const auto t0 = Clock::now();
    const filter::FrameResult r = filter_->step(frame, window_.crop_pose(crop), f.odometry, road, fix ? &*fix : nullptr);
    filter_seconds_ += seconds_since(t0);
    if (context_.inspect) context_.inspect({i, &frame, crop, &filter_->belief(), window_.origin_u(), window_.origin_v()});
    if (context_.options.keep_beliefs) {
      const auto marginal = filter_->belief().position_marginal();
      beliefs_.insert(beliefs_.end(), marginal.begin(), marginal.end());
      belief_origins_.push_back({window_.origin_u(), window_.origin_v()});
    }
    frames.release(i);
    FrameEstimate e;
    e.x_m = window_.x_of(r.pose.u);
    e.y_m = window_.y_of(r.pose.v);
    e.grid_heading_deg = r.pose.heading_deg;
    e.entropy = r.frame_entropy;
    e.etu_weight = r.etu_weight;
    e.relocalized = r.relocalized;
    // Keep the window on the vehicle.
    keep_in_window(r.pose.u, r.pose.v);
    return e;
  }

  void finish(RouteResult& result) override {
    LocalizationMode::finish(result);
    result.recentres += recentres_;
    if (context_.options.keep_beliefs) {
      result.belief_width = config_.width;
      result.belief_height = config_.height;
      result.beliefs = std::move(beliefs_);
      result.belief_origins = std::move(belief_origins_);
    }
  }

 private:
  // The first frame: centred on its GPS fix when it has one (the fix's Gaussian is the prior),
  // else on its crop with a uniform prior.
  void start(const RouteFrame& f, const GridCrop& crop) {
    filter_.emplace(config_);
    double cx = crop.x, cy = crop.y;
    if (f.gps) {
      const auto g = context_.cache.metadata().projection().forward(f.gps->where);
      cx = g.x_m;
      cy = g.y_m;
    }
    window_.centre_on(cx, cy);
    if (f.gps) {
      filter_->reset_gaussian(window_.u_of(cx), window_.v_of(cy), f.gps->sigma_m);
    } else {
      filter_->reset_uniform();
    }
  }

  // Re-centres the window by whole cells on window position (u, v) when it lies within the
  // margin of an edge (or outside).
  void keep_in_window(double u, double v) {
    const auto shift = window_.recentre_shift(u, v, context_.options.recentre_margin);
    if (!shift) return;
    filter_->recentre((*shift)[0], (*shift)[1]);
    window_.shift((*shift)[0], (*shift)[1]);
    ++recentres_;
  }

  filter::FilterConfig config_;
  RegionWindow window_;
  std::optional<filter::SeqLocFilter> filter_;
  int recentres_ = 0;
  std::vector<float> beliefs_;
  std::vector<std::array<std::int64_t, 2>> belief_origins_;
};

}  // namespace

std::unique_ptr<LocalizationMode> make_sequential(const RouteContext& context, bool online) {
  return std::make_unique<SequentialMode>(context, online);
}

}  // namespace seqloc::pipeline::modes
