// DeviceFilter: SeqLocFilter's step (seqloc_filter.cpp) with the belief in an engine's memory.
// The order of the stages, and every scalar decided between them (the power, ETU's weight, the
// value outside the crop, the hold's release, the relocalization flag), is the CPU filter's; the
// engine runs the passes over the belief and the frame.

#include "seqloc/gpu/device_filter.hpp"

#include <algorithm>
#include <cmath>
#include <string>
#include <vector>

#include "engine.hpp"
#include "seqloc/core/angles.hpp"
#include "seqloc/core/units.hpp"

namespace seqloc::gpu {
namespace {

using core::kCellM;
using core::kDegToRad;
using filter::bin_heading_deg;
using filter::FilterError;
using filter::FrameResult;
using filter::Pose;

/// The window bins' reading of a frame's bins (filter/resample.cpp's sample_slice).
std::vector<HeadingBlend> heading_blends(int headings, int frame_bins, double rotation_deg) {
  std::vector<HeadingBlend> blends(static_cast<std::size_t>(headings));
  for (int k = 0; k < headings; ++k) {
    blends[static_cast<std::size_t>(k)] =
        filter::math::heading_blend(bin_heading_deg(k, headings), rotation_deg, frame_bins);
  }
  return blends;
}

/// Where window cells (`width` x `height`) read a frame whose cells are `cell_m` window-cell
/// metres (filter/resample.cpp's sample_slice).
CropGeometry crop_geometry(const filter::PreparedFrame& frame, double cell_m, const filter::CropPose& crop, int width,
                           int height) {
  CropGeometry g;
  const double scale = kCellM / cell_m;
  g.translate = crop.rotation_deg == 0.0 && scale == 1.0;
  if (g.translate) {
    g.translation = filter::math::make_translation(frame.width, frame.height, width, height,
                                                   (frame.width - 1) / 2.0 - crop.centre_u,
                                                   (frame.height - 1) / 2.0 - crop.centre_v);
  } else {
    const double r = crop.rotation_deg * kDegToRad;
    g.map = {crop.centre_u, crop.centre_v, std::cos(r), std::sin(r), scale, frame.width, frame.height};
  }
  return g;
}

filter::FilterConfig checked(const filter::FilterConfig& config) {
  config.validate();
  if (config.motion_noise) {
    throw FilterError("the CUDA backend has no motion noise yet: run without --motion-noise or on the CPU",
                      ErrorCategory::usage);
  }
  if (config.self_calibrate && config.self_calibration_bank) {
    throw FilterError(
        "the CUDA backend has no self-calibration bank yet: run without self_calibration_bank or on the CPU",
        ErrorCategory::usage);
  }
  return config;
}

}  // namespace

const char* backend_name(Backend backend) { return backend == Backend::cuda ? "cuda" : "host"; }

DeviceFilter::DeviceFilter(const filter::FilterConfig& config, Backend backend)
    : config_(checked(config)),
      backend_(backend),
      engine_(make_engine(config_, backend)),
      estimator_(config_.self_calibration_prior_octaves, config_.self_calibration_outlier_share,
                 {config_.self_calibration_hold_below_octaves, config_.self_calibration_hold_above_octaves,
                  config_.self_calibration_hold_share, config_.self_calibration_hold_follow_octaves}),
      decisions_(config_) {
  reset_uniform();
}

DeviceFilter::~DeviceFilter() = default;

void DeviceFilter::reset_uniform() {
  const std::size_t cells = static_cast<std::size_t>(config_.width) * config_.height * config_.headings;
  engine_->fill_belief(static_cast<float>(1.0 / static_cast<double>(cells)));
  start_sequence();
}

void DeviceFilter::reset_gaussian(double u, double v, double sigma_m) {
  filter::BeliefVolume prior(config_.width, config_.height, config_.headings);
  prior.set_gaussian(u, v, sigma_m / kCellM);
  engine_->upload_belief(prior.data());
  start_sequence();
}

void DeviceFilter::start_sequence() {
  cached_min_.reset();
  first_ = true;
  last_estimate_.reset();
  estimator_.reset();
  decisions_.reset();
}

filter::BeliefVolume DeviceFilter::belief() const {
  filter::BeliefVolume out(config_.width, config_.height, config_.headings);
  engine_->download_belief(out.data());
  return out;
}

void DeviceFilter::set_belief(const filter::BeliefVolume& belief) {
  if (belief.width() != config_.width || belief.height() != config_.height || belief.headings() != config_.headings) {
    throw FilterError("set_belief: the belief is " + std::to_string(belief.width()) + " x " +
                          std::to_string(belief.height()) + " x " + std::to_string(belief.headings()) +
                          ", the filter's window " + std::to_string(config_.width) + " x " +
                          std::to_string(config_.height) + " x " + std::to_string(config_.headings),
                      ErrorCategory::usage);
  }
  engine_->upload_belief(belief.data());
  cached_min_.reset();
}

void DeviceFilter::rebase(const filter::BeliefVolume& belief, const std::optional<Pose>& last_estimate) {
  set_belief(belief);
  last_estimate_ = last_estimate;
}

void DeviceFilter::recentre(int du, int dv) {
  engine_->recentre(du, dv);
  cached_min_.reset();
  decisions_.recentre(du, dv);
  if (last_estimate_) {
    last_estimate_->u -= du;
    last_estimate_->v -= dv;
  }
}

void DeviceFilter::predict(const filter::Odometry& odometry) {
  const int R = config_.headings;
  const float fill = cached_min_ ? *cached_min_ : engine_->least();
  // filter/resample.cpp's warp_volume: new bin k takes source bins k + s and k + s + 1.
  const double p = odometry.yaw_deg * R / 360.0;
  const double floor_p = std::floor(p);
  const auto a = static_cast<float>(p - floor_p);
  const int s = static_cast<int>(((static_cast<long long>(floor_p) % R) + R) % R);
  std::vector<filter::math::Translation> by_bin(static_cast<std::size_t>(R));
  for (int j = 0; j < R; ++j) {
    double du = 0, dv = 0;
    filter::math::displacement_cells(odometry.forward_m, odometry.left_m, bin_heading_deg(j, R), kCellM, du, dv);
    by_bin[static_cast<std::size_t>(j)] =
        filter::math::make_translation(config_.width, config_.height, config_.width, config_.height, -du, -dv);
  }
  engine_->predict(by_bin, s, a, fill);
  cached_min_.reset();
}

FrameResult DeviceFilter::step(const filter::PreparedFrame& frame, const filter::CropPose& crop,
                               const filter::Odometry& odometry, std::span<const float> road_distance_m,
                               const std::optional<filter::GpsFix>& gps) {
  if (!first_) {
    predict(odometry);
    decisions_.track(odometry, last_estimate_);
  }
  FrameResult result = update(frame, crop, road_distance_m, gps);
  if (last_estimate_ && !first_) result.relocalized = decisions_.relocalized(*last_estimate_, odometry, result.argmax);
  last_estimate_ = result.pose;
  first_ = false;
  return result;
}

FrameResult DeviceFilter::weigh(const filter::PreparedFrame& frame,
                                const std::optional<filter::FrameWeighting>& weighting, bool calibrating) {
  FrameResult result;
  result.volume_power = decisions_.frame_power(weighting, calibrating, estimator_.power());
  // The powered frame's peak and entropy (SeqLocFilter's scan_frame): -log Z and
  // log Z - k sum(e^{k r} r) / Z.
  float peak = weighting.has_value() ? weighting->peak_log_prob : frame.max_log_prob;
  double entropy = frame.entropy;
  if (calibrating && result.volume_power != 1.0) {
    const FrameSums sums = engine_->frame_sums(static_cast<float>(result.volume_power), frame.max_log_prob);
    const double log_z = std::log(sums.z);
    peak = static_cast<float>(-log_z);
    entropy = std::clamp((log_z - result.volume_power * sums.zr / sums.z) / frame.log_cells, 0.0, 1.0);
  }
  result.frame_entropy = entropy;
  result.etu_weight = weighting ? weighting->etu_weight : decisions_.etu_weight_of(frame.entropy, entropy);
  result.weighting = {result.volume_power, result.etu_weight, peak};
  return result;
}

void DeviceFilter::retemper() {
  // SeqLocFilter::retemper: once the hold releases, the belief is raised to the ratio of the new
  // power to the one its frames went in at (StepDecisions::hold_ratio).
  const auto ratio = static_cast<float>(decisions_.belief_ratio(estimator_.power(), estimator_.held()));
  if (first_ || ratio == 1.0f) return;
  if (engine_->raise(ratio)) cached_min_.reset();
}

FrameResult DeviceFilter::update(const filter::PreparedFrame& frame, const filter::CropPose& crop,
                                 std::span<const float> road_distance_m, const std::optional<filter::GpsFix>& gps,
                                 const std::optional<filter::FrameWeighting>& weighting) {
  const std::size_t slice = static_cast<std::size_t>(config_.width) * config_.height;
  if (config_.mgr && road_distance_m.empty())
    throw FilterError("MGR is on but no road-distance window was given", ErrorCategory::usage);
  if (config_.mgr && road_distance_m.size() != slice) {
    throw FilterError("the road-distance window holds " + std::to_string(road_distance_m.size()) + " values, not " +
                          std::to_string(config_.width) + " x " + std::to_string(config_.height),
                      ErrorCategory::usage);
  }
  const bool calibrating = config_.self_calibrate && !weighting;
  engine_->load_frame(frame);
  if (calibrating) decisions_.observe(frame, crop);
  FrameResult result = weigh(frame, weighting, calibrating);
  if (calibrating) retemper();

  // The tempered likelihood q^w, scaled by its peak, and the value of a cell outside the crop.
  const auto w = static_cast<float>(result.etu_weight);
  engine_->temper(static_cast<float>(w * result.volume_power), frame.max_log_prob);
  const float outside =
      static_cast<float>(std::exp(w * (-frame.log_cells - config_.outside_crop_nats - result.weighting.peak_log_prob)));

  if (calibrating) engine_->pool_coarse();  // the predicted belief, before the frame goes in
  const std::vector<HeadingBlend> blends = heading_blends(config_.headings, frame.bins, crop.rotation_deg);
  const CropGeometry geometry = crop_geometry(frame, frame.cell_m, crop, config_.width, config_.height);
  const std::vector<float> gps_term = filter::gps_prior_factor(config_, gps);
  double total = engine_->multiply(blends, geometry, outside, gps_term, true);
  if (calibrating) estimator_.add(judge(frame, crop));
  if (!(total > 0) || !std::isfinite(total)) {
    // Belief and frame share no support that float can represent: the frame alone decides.
    total = engine_->multiply(blends, geometry, outside, gps_term, false);
    if (!(total > 0)) throw FilterError("the frame volume has no mass inside the window");
  }

  // Normalization and MGR's blend with the road prior (SeqLocFilter::normalize).
  if (config_.mgr && (road_.size() != road_distance_m.size() ||
                      !std::equal(road_distance_m.begin(), road_distance_m.end(), road_.begin()))) {
    // A window that has not moved keeps its road prior on the device.
    engine_->set_road_prior(road_distance_m, config_.mgr_sigma_m, static_cast<float>(config_.mgr_epsilon));
    road_.assign(road_distance_m.begin(), road_distance_m.end());
  }
  const auto keep = static_cast<float>((config_.mgr ? 1.0 - config_.mgr_epsilon : 1.0) / total);
  const PeakCell peak = engine_->normalize(keep, config_.mgr);
  cached_min_ = peak.least;
  result.peak_log_belief = std::log(peak.value);
  result.argmax = {static_cast<double>(peak.u), static_cast<double>(peak.v), bin_heading_deg(peak.k, config_.headings)};
  result.pose = decisions_.refine(
      peak.u, peak.v, peak.k, config_.width, config_.height,
      [this](int u0, int v0, int u1, int v1, std::span<double> out) { engine_->position_masses(u0, v0, u1, v1, out); },
      [this](int u, int v, int k) { return static_cast<double>(engine_->value(u, v, k)); });
  return result;
}

filter::CalibrationEvidence DeviceFilter::judge(const filter::PreparedFrame& frame, const filter::CropPose& crop) {
  // filter::coarse_evidence with its sums made by the engine: the coarse grid's cells are 2 x 2
  // window cells, so the frame's cells are half as large in them and the crop's centre moves.
  const int coarse_r = config_.headings / filter::math::calibration_bins(config_.headings);
  const int coarse_w = (config_.width + 1) / 2, coarse_h = (config_.height + 1) / 2;
  const filter::CropPose at{(crop.centre_u - 0.5) / 2, (crop.centre_v - 0.5) / 2, crop.rotation_deg};
  JudgeSetup setup;
  setup.blend = heading_blends(coarse_r, frame.bins, crop.rotation_deg);
  setup.geometry = crop_geometry(frame, frame.cell_m / 2, at, coarse_w, coarse_h);
  setup.frame_stride = filter::math::calibration_bins(frame.bins);
  setup.peak = frame.max_log_prob;
  setup.max_depth = static_cast<float>(filter::DepthHistogram::kMaxDepthNats);
  setup.per_nat = static_cast<float>(1 / filter::DepthHistogram::kBinNats);
  setup.last_bin = static_cast<int>(filter::DepthHistogram::bins()) - 1;
  setup.count_scale = filter::DepthHistogram::kCount;
  setup.mass_scale = filter::DepthHistogram::kMass;
  const JudgeSums sums = engine_->judge(setup);
  filter::CalibrationEvidence evidence;
  evidence.frame_cells.add_bins(sums.frame_weight, sums.frame_depth);
  evidence.belief_in_crop.add_bins(sums.mass_weight, sums.mass_depth);
  evidence.belief_outside = sums.outside_mass;
  evidence.log_outside = -frame.log_cells - config_.outside_crop_nats;
  const double cells_per_cell = 4.0 * config_.headings / coarse_r;
  evidence.window_cells = static_cast<double>(coarse_w) * coarse_h * coarse_r * cells_per_cell;
  evidence.outside_cells = static_cast<double>(sums.outside_cells) * cells_per_cell;
  return evidence;
}

}  // namespace seqloc::gpu
