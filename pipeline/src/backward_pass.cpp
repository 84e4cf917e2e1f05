#include "seqloc/pipeline/backward_pass.hpp"

#include <utility>

namespace seqloc::pipeline {
namespace {

filter::FilterConfig replay_config(filter::FilterConfig config) {
  config.self_calibrate = false;  // every frame comes with its weighting: no estimator, no buffers for it
  return config;
}

// Moves a window and the belief over it to `origin` by whole cells.
template <class Filter>
void move_window(Filter& filter, RegionWindow& window, const std::array<std::int64_t, 2>& origin) {
  const auto du = static_cast<int>(origin[0] - window.origin_u());
  const auto dv = static_cast<int>(origin[1] - window.origin_v());
  if (du == 0 && dv == 0) return;
  filter.recentre(du, dv);
  window.shift(du, dv);
}

}  // namespace

BackwardPass::BackwardPass(raster::CacheReader& cache, const filter::FilterConfig& config)
    : config_(config), window_(cache, config.width, config.height), filter_(config) {}

void BackwardPass::start(const StepRecord& last) { start(last, window_.cache()); }

void BackwardPass::start(const StepRecord& last, raster::CacheReader& region) {
  if (&region != &window_.cache()) window_ = RegionWindow(region, window_.width(), window_.height());
  window_.move_to(last.origin_after[0], last.origin_after[1]);
  filter_.reset();
}

FrameEstimate BackwardPass::estimate(const filter::BeliefVolume& alpha, const StepRecord& record) {
  // The smoothed posterior: the uncertainty is its own, not the forward filter's.
  if (!posterior_) posterior_.emplace(config_.width, config_.height, config_.headings);
  const filter::FrameResult r = filter::smoothed_result(alpha, filter_.belief(), config_, &*posterior_);
  FrameEstimate e = record.filtered;
  e.x_m = window_.x_of(r.pose.u);
  e.y_m = window_.y_of(r.pose.v);
  e.grid_heading_deg = r.pose.heading_deg;
  e.uncertainty = uncertainty_of(*posterior_, r.pose, config_.threads);
  return e;
}

void BackwardPass::step_back(const StepRecord& record, const filter::PreparedFrame& frame, const StepRecord& previous) {
  step_back(record, frame, previous, window_.cache());
}

void BackwardPass::step_back(const StepRecord& record, const filter::PreparedFrame& frame, const StepRecord& previous,
                             raster::CacheReader& previous_region) {
  // beta stands in the window the forward belief ended the step in; the frame was taken in where
  // the window was before that step's re-centring.
  move_window(filter_, window_, record.origin);
  const std::span<const float> road = config_.mgr ? window_.road_distance_m() : std::span<const float>{};
  filter_.absorb(frame, record.crop, record.weighting, road, record.fix);
  filter_.step_back(record.odometry);
  if (&previous_region == &window_.cache()) {
    move_window(filter_, window_, previous.origin_after);
    return;
  }
  RegionWindow there(previous_region, window_.width(), window_.height());
  there.move_to(previous.origin_after[0], previous.origin_after[1]);
  filter_.rebase(carry_belief(filter_.belief(), window_, there));
  window_ = there;
}

ForwardReplay::ForwardReplay(raster::CacheReader& cache, const filter::FilterConfig& config)
    : config_(replay_config(config)), window_(cache, config.width, config.height), filter_(config_) {}

void ForwardReplay::resume(const filter::BeliefVolume& alpha, const StepRecord& record) {
  window_.move_to(record.origin_after[0], record.origin_after[1]);
  filter_.belief() = alpha;
}

filter::FrameResult ForwardReplay::step(const StepRecord& record, const filter::PreparedFrame& frame, bool predict) {
  // The window moves as it moved the first time: before the step (onto the frame's crop), then
  // after it (onto the estimate), each a move of its own (a move drops the mass that leaves the
  // window and fills what enters).
  move_window(filter_, window_, record.origin);
  if (predict) filter_.predict(record.odometry);
  return update(record, frame);
}

filter::FrameResult ForwardReplay::step(const StepRecord& record, const filter::PreparedFrame& frame,
                                        filter::BeliefVolume& previous) {
  if (record.origin[0] != window_.origin_u() || record.origin[1] != window_.origin_v()) {
    previous = std::as_const(filter_).belief();  // the window moves before the motion: a copy
    return step(record, frame);
  }
  filter_.predict(record.odometry, previous);
  return update(record, frame);
}

filter::FrameResult ForwardReplay::update(const StepRecord& record, const filter::PreparedFrame& frame) {
  const std::span<const float> road = config_.mgr ? window_.road_distance_m() : std::span<const float>{};
  filter::FrameResult result = filter_.update(frame, record.crop, road, record.fix, record.weighting);
  move_window(filter_, window_, record.origin_after);
  return result;
}

}  // namespace seqloc::pipeline
