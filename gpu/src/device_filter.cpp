// DeviceFilter: a SeqLoc step with the belief in an engine's memory. The step's sequence and every
// decision in it are StepDecisions' (filter/step_decisions.hpp), as for the CPU filter; this is the
// cell work behind filter::CellWork, run by the engine's passes over the belief and the frame.

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
    : config_(checked(config)), backend_(backend), engine_(make_engine(config_, backend)), decisions_(config_) {
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
  decisions_.rebase(last_estimate);
}

void DeviceFilter::recentre(int du, int dv) {
  engine_->recentre(du, dv);
  cached_min_.reset();
  decisions_.recentre(du, dv);
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

void DeviceFilter::load(const filter::PreparedFrame& frame, bool /*estimating*/) { engine_->load_frame(frame); }

filter::FrameShape DeviceFilter::powered_shape(const filter::PreparedFrame& frame, double power) {
  // -log Z and log Z - k sum(e^{k r} r) / Z (SeqLocFilter's scan_frame); the frame's own at 1.
  if (power == 1.0) return {frame.max_log_prob, frame.entropy};
  const FrameSums sums = engine_->frame_sums(static_cast<float>(power), frame.max_log_prob);
  const double log_z = std::log(sums.z);
  return {static_cast<float>(-log_z), std::clamp((log_z - power * sums.zr / sums.z) / frame.log_cells, 0.0, 1.0)};
}

void DeviceFilter::raise(float ratio) {
  if (engine_->raise(ratio)) cached_min_.reset();
}

std::optional<filter::FrameShape> DeviceFilter::temper(const filter::PreparedFrame& frame, float exponent,
                                                       std::optional<double> shape_power) {
  engine_->temper(exponent, frame.max_log_prob);
  if (!shape_power) return std::nullopt;
  return powered_shape(frame, *shape_power);
}

double DeviceFilter::multiply_in(const filter::PreparedFrame& frame, const filter::CropPose& crop, float outside,
                                 std::span<const float> gps_term, bool with_prior, bool pool) {
  if (pool) engine_->pool_coarse();  // the predicted belief, before the frame goes in
  const std::vector<HeadingBlend> blends = heading_blends(config_.headings, frame.bins, crop.rotation_deg);
  const CropGeometry geometry = crop_geometry(frame, frame.cell_m, crop, config_.width, config_.height);
  return engine_->multiply(blends, geometry, outside, gps_term, with_prior);
}

filter::BeliefPeak DeviceFilter::normalize(double total, std::span<const float> road_distance_m) {
  if (config_.mgr && (road_.size() != road_distance_m.size() ||
                      !std::equal(road_distance_m.begin(), road_distance_m.end(), road_.begin()))) {
    // A window that has not moved keeps its road prior on the device.
    engine_->set_road_prior(road_distance_m, config_.mgr_sigma_m, static_cast<float>(config_.mgr_epsilon));
    road_.assign(road_distance_m.begin(), road_distance_m.end());
  }
  const auto keep = static_cast<float>((config_.mgr ? 1.0 - config_.mgr_epsilon : 1.0) / total);
  const PeakCell peak = engine_->normalize(keep, config_.mgr);
  cached_min_ = peak.least;
  return {peak.u, peak.v, peak.k, peak.value};
}

filter::PositionMasses DeviceFilter::position_masses() {
  return
      [this](int u0, int v0, int u1, int v1, std::span<double> out) { engine_->position_masses(u0, v0, u1, v1, out); };
}

filter::CellValue DeviceFilter::cell_value() {
  return [this](int u, int v, int k) { return static_cast<double>(engine_->value(u, v, k)); };
}

const filter::CalibrationEvidence& DeviceFilter::evidence(const filter::PreparedFrame& frame,
                                                          const filter::CropPose& crop) {
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
  filter::CalibrationEvidence& evidence = evidence_;
  evidence.clear();
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
