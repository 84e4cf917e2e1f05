#include "seqloc/pipeline/sequential_localizer.hpp"

#include <cmath>
#include <stdexcept>
#include <string>

namespace seqloc::pipeline {
namespace {

filter::FilterConfig mode_config(const filter::FilterConfig& config, bool online) {
  filter::FilterConfig c = config;
  if (online) c.etu = c.mgr = c.pas = c.self_calibrate = false;
  return c;
}

}  // namespace

std::optional<GridFix> frame_gps_fix(const io::RouteFrame& f, const osm::RegionProjection& projection) {
  if (!f.gps) return std::nullopt;
  const auto g = projection.forward(f.gps->where);
  return GridFix{g.x_m, g.y_m, f.gps->sigma_m};
}

SequentialLocalizer::SequentialLocalizer(raster::CacheReader& cache, const filter::FilterConfig& config, bool online,
                                         double recentre_margin, int lag, Device device)
    : config_(mode_config(config, online)),
      recentre_margin_(recentre_margin),
      lag_(lag),
      device_(device),
      window_(cache, config_.width, config_.height) {
  if (lag < 0) throw filter::FilterError("lag = " + std::to_string(lag) + ": must be >= 0 frames");
  if (lag > 0) backward_.emplace(cache, config_);
}

FrameEstimate SequentialLocalizer::step(const filter::PreparedFrame& frame, const GridCrop& crop,
                                        const filter::Odometry& odometry, const std::optional<GridFix>& gps) {
  // The early replay keeps the route's first frames (FilterConfig::self_calibration_replay_frames):
  // from the first step, which starts it, while it keeps them.
  const bool replay_may_keep =
      config_.self_calibrate && config_.self_calibration_replay_frames > 0 && (!filter_ || early_);
  if (lag_ == 0 && !replay_may_keep) {
    // Nothing keeps the frame: no copy.
    return step(std::shared_ptr<const filter::PreparedFrame>(&frame, [](const filter::PreparedFrame*) {}), crop,
                odometry, gps);
  }
  return step(std::make_shared<const filter::PreparedFrame>(frame), crop, odometry, gps);
}

FrameEstimate SequentialLocalizer::step(std::shared_ptr<const filter::PreparedFrame> frame, const GridCrop& crop,
                                        const filter::Odometry& odometry, const std::optional<GridFix>& gps) {
  if (!filter_) {
    // The first frame: centred on its GPS fix when it has one (the fix's Gaussian is the prior),
    // else on its crop with a uniform prior.
    filter_.emplace(config_, device_);
    window_.centre_on(gps ? gps->x_m : crop.x, gps ? gps->y_m : crop.y);
    if (gps) {
      filter_->reset_gaussian(window_.u_of(gps->x_m), window_.v_of(gps->y_m), gps->sigma_m);
    } else {
      filter_->reset_uniform();
    }
    if (config_.self_calibrate && config_.self_calibration_replay_frames > 0) {
      early_.emplace(Early{filter_->belief(), {window_.origin_u(), window_.origin_v()}, {}, {}, 0});
    }
  }
  // A crop far from the window (the estimate wandered off while the frames' evidence stayed
  // around the GPS-like crops) brings the window to it: evidence outside the window is lost.
  keep_in_window(window_.u_of(crop.x), window_.v_of(crop.y));
  std::optional<filter::GpsFix> fix;
  if (config_.gps_prior && gps) fix = filter::GpsFix{window_.u_of(gps->x_m), window_.v_of(gps->y_m), gps->sigma_m};
  const std::span<const float> road = config_.mgr ? window_.road_distance_m() : std::span<const float>{};
  const filter::CropPose crop_pose = window_.crop_pose(crop);
  const std::array<std::int64_t, 2> origin{window_.origin_u(), window_.origin_v()};
  filter::FrameResult r = filter_->step(*frame, crop_pose, odometry, road, fix);
  if (early_) r = replay_early(frame, StepRecord{origin, origin, crop_pose, odometry, fix, r.weighting, {}}, r);
  FrameEstimate e;
  e.x_m = window_.x_of(r.pose.u);
  e.y_m = window_.y_of(r.pose.v);
  e.grid_heading_deg = r.pose.heading_deg;
  e.entropy = r.frame_entropy;
  e.etu_weight = r.etu_weight;
  e.volume_power = r.volume_power;
  e.relocalized = r.relocalized;
  // With a lag, the estimates handed out are the backward pass's, with the smoothed posterior's
  // uncertainty.
  if (uncertainty_ && lag_ == 0) e.uncertainty = uncertainty_of(filter_->belief(), r.pose, config_.threads);
  last_ = StepRecord{origin, {}, crop_pose, odometry, fix, r.weighting, e};
  // Keep the window on the vehicle.
  keep_in_window(r.pose.u, r.pose.v);
  last_.origin_after = {window_.origin_u(), window_.origin_v()};
  if (early_) {
    early_->records.back().origin_after = last_.origin_after;
    early_->records.back().filtered = e;
    if (early_->records.size() >= static_cast<std::size_t>(config_.self_calibration_replay_frames)) early_.reset();
  }

  const std::size_t index = stepped_++;
  if (lag_ == 0) {
    final_.emplace_back(index, e);
    return e;
  }
  // Fixed lag: keep this frame's forward belief (reusing the storage of one that left), then the
  // frame L back is final.
  if (waiting_.size() > static_cast<std::size_t>(lag_)) {
    Waiting reused = std::move(waiting_.front());
    waiting_.pop_front();
    reused.alpha = filter_->belief();
    waiting_.push_back({index, &window_.cache(), last_, std::move(frame), std::move(reused.alpha)});
  } else {
    waiting_.push_back({index, &window_.cache(), last_, std::move(frame), filter_->belief()});
  }
  if (waiting_.size() == static_cast<std::size_t>(lag_) + 1) smooth_waiting(0, 1);
  return e;
}

// One backward pass from the last waiting frame down to waiting_[from]; the first `to_emit` frames
// from `from` on get their smoothed estimates.
void SequentialLocalizer::smooth_waiting(std::size_t from, std::size_t to_emit) {
  backward_->start(waiting_.back().record, *waiting_.back().region);
  std::vector<std::pair<std::size_t, FrameEstimate>> done;
  for (std::size_t j = waiting_.size(); j-- > from;) {
    if (j < from + to_emit) done.emplace_back(waiting_[j].index, backward_->estimate(waiting_[j].alpha, waiting_[j].record));
    if (j > from) {
      backward_->step_back(waiting_[j].record, *waiting_[j].frame, waiting_[j - 1].record, *waiting_[j - 1].region);
    }
  }
  final_.insert(final_.end(), done.rbegin(), done.rend());
}

void SequentialLocalizer::finish() {
  if (waiting_.empty()) return;
  // The frame L back was emitted at the last step (when there were L + 1); the rest now.
  const std::size_t from = waiting_.size() == static_cast<std::size_t>(lag_) + 1 ? 1 : 0;
  if (from < waiting_.size()) smooth_waiting(from, waiting_.size() - from);
  waiting_.clear();
}

filter::FrameResult SequentialLocalizer::replay_early(std::shared_ptr<const filter::PreparedFrame> frame,
                                                      const StepRecord& record, const filter::FrameResult& r) {
  Early& early = *early_;
  early.records.push_back(record);
  early.frames.push_back(std::move(frame));
  std::vector<double> powers;
  for (const StepRecord& kept : early.records) powers.push_back(kept.weighting.volume_power);
  if (!filter::StepDecisions::replay_due(r.volume_power, powers, early.replays)) return r;
  ++early.replays;
  // The route again from its prior, each kept frame at the newest frame's power (its ETU weight
  // as it was: ETU's route reference reads the frames as given), the window moving as it moved.
  ForwardReplay replay(window_.cache(), config_);
  StepRecord start;
  start.origin_after = early.origin;
  replay.resume(early.prior, start);
  filter::FrameResult last = r;
  const std::size_t first_index = stepped_ + 1 - early.records.size();
  for (std::size_t i = 0; i < early.records.size(); ++i) {
    StepRecord& kept = early.records[i];
    const filter::PreparedFrame& f = *early.frames[i];
    kept.weighting.volume_power = r.volume_power;
    kept.weighting.peak_log_prob = filter::powered_peak_log_prob(f, r.volume_power, config_.threads);
    last = replay.step(kept, f, /*predict=*/i > 0);
    const std::size_t index = first_index + i;
    Rewrite rewrite{index, kept, std::nullopt};
    if (alphas_wanted_ && alphas_wanted_(index)) rewrite.alpha = replay.belief();
    for (Waiting& w : waiting_) {  // a lag's frames keep their forward belief and weighting
      if (w.index != index) continue;
      w.record.weighting = kept.weighting;
      w.alpha = replay.belief();
    }
    if (i + 1 < early.records.size()) rewritten_.push_back(std::move(rewrite));
  }
  filter_->rebase(replay.belief(), last.pose);
  last.relocalized = r.relocalized;  // against the estimate handed out before, as the step judged it
  last.volume_power = r.volume_power;
  last.etu_weight = r.etu_weight;
  last.frame_entropy = r.frame_entropy;
  last.weighting = early.records.back().weighting;
  return last;
}

std::vector<SequentialLocalizer::Rewrite> SequentialLocalizer::take_rewritten() {
  std::vector<Rewrite> out;
  out.swap(rewritten_);
  return out;
}

void SequentialLocalizer::hand_over(raster::CacheReader& next) {
  early_.reset();  // the kept frames were taken in the region the route leaves
  RegionWindow moved(next, config_.width, config_.height);
  if (!filter_) {  // nothing stepped yet: the first step places the window
    window_ = moved;
    return;
  }
  // The new window centred where the old one was.
  const RegionWindow& old = window_;
  const int centre_u = old.width() / 2, centre_v = old.height() / 2;  // the window's centre cell
  const filter::Pose centre = carry_pose({static_cast<double>(centre_u), static_cast<double>(centre_v), 0}, old, moved);
  moved.centre_on(moved.x_of(centre.u), moved.y_of(centre.v));
  std::optional<filter::Pose> last = filter_->last_estimate();
  if (last) last = carry_pose(*last, old, moved);
  filter_->rebase(carry_belief(filter_->belief(), old, moved), last);
  window_ = moved;
}

std::vector<std::pair<std::size_t, FrameEstimate>> SequentialLocalizer::take_final() {
  std::vector<std::pair<std::size_t, FrameEstimate>> out;
  out.swap(final_);
  return out;
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
