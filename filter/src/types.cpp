#include <sstream>

#include "seqloc/filter/config.hpp"
#include "seqloc/filter/types.hpp"

namespace seqloc::filter {

std::span<const FilterConfigField> filter_config_fields() {
  using C = FilterConfig;
  static const FilterConfigField kFields[] = {
      {"width", &C::width, "Belief window width, cells of 0.5 m"},
      {"height", &C::height, "Belief window height, cells of 0.5 m"},
      {"headings", &C::headings, "Heading bins R"},
      {"etu", &C::etu, "Entropy-Tempered Uncertainty"},
      {"mgr", &C::mgr, "Map-Guided Relocalization"},
      {"pas", &C::pas, "Peak-Anchored Smoothing"},
      {"etu_reference_entropy", &C::etu_reference_entropy,
       "ETU relative to this normalized entropy: w = min(1, (1 - H) / (1 - H_ref)); 0: the paper's 1 - H"},
      {"etu_route_reference", &C::etu_route_reference,
       "ETU relative to the median entropy of the route's frames so far (as given) instead of --etu-reference"},
      {"mgr_epsilon", &C::mgr_epsilon, "MGR's eps: the share of road-prior mass mixed into the belief"},
      {"mgr_sigma_m", &C::mgr_sigma_m, "MGR's road-prior sigma in metres"},
      {"pas_radius", &C::pas_radius, "PAS radius in cells"},
      {"outside_crop_nats", &C::outside_crop_nats,
       "Window cells outside a frame's crop get log(1/M) minus this (0: the paper's rule)"},
      {"self_calibrate", &C::self_calibrate,
       "self-calibration: raise each volume to the power its predecessors' predictive likelihood favours"},
      {"self_calibration_bank", &C::self_calibration_bank,
       "Self-calibration: judge each power by the route's likelihood under a coarse filter run at it "
       "(off: by the one-step predictive likelihood, with the hold)"},
      {"self_calibration_prior_octaves", &C::self_calibration_prior_octaves,
       "Self-calibration: sigma of the prior on log2 of the power (octaves)"},
      {"self_calibration_outlier_share", &C::self_calibration_outlier_share,
       "Self-calibration: share of a uniform belief each frame is also judged against"},
      {"self_calibration_hold_below_octaves", &C::self_calibration_hold_below_octaves,
       "Self-calibration: powers down to this many octaves under 1 count as calibrated"},
      {"self_calibration_hold_above_octaves", &C::self_calibration_hold_above_octaves,
       "Self-calibration: powers up to this many octaves over 1 count as calibrated"},
      {"self_calibration_hold_follow_octaves", &C::self_calibration_hold_follow_octaves,
       "Self-calibration: held, an estimate this many octaves under 1 is followed all the same"},
      {"self_calibration_hold_share", &C::self_calibration_hold_share,
       "Self-calibration: the power stays 1 while the posterior keeps this share on calibrated powers"},
      {"self_calibration_replay_frames", &C::self_calibration_replay_frames,
       "Self-calibration: the route's first this many frames are filtered again at the power it settles on (0: "
       "never)"},
      {"self_calibration_shared_lag", &C::self_calibration_shared_lag,
       "Self-calibration: the longest lag (frames) at which the frames' peaks are compared to read how much "
       "consecutive frames share their errors (0: off)"},
      {"self_calibration_sharpness", &C::self_calibration_sharpness,
       "Self-calibration: temper frames sharper than the route's typical frame where its sharper frames predict worse"},
      {"relocalization_jump_m", &C::relocalization_jump_m, "An argmax jump beyond this (m) is flagged relocalized"},
      {"subbin_heading", &C::subbin_heading, "Refine the heading between bins (beyond the paper)"},
      {"subbin_half_width", &C::subbin_half_width, "Bins each side of the heading in that refinement"},
      {"motion_noise", &C::motion_noise, "Diffuse the belief with the step length (beyond the paper)"},
      {"motion_noise_xy_per_m", &C::motion_noise_xy_per_m, "Motion noise: position sigma (m) per metre driven"},
      {"motion_noise_deg_per_m", &C::motion_noise_deg_per_m, "Motion noise: heading sigma (degrees) per metre driven"},
      {"gps_prior", &C::gps_prior, "Use every frame's GPS fix as a prior term (beyond the paper)"},
      {"threads", &C::threads, "Worker threads of one filter step"},
  };
  return kFields;
}

FilterConfig paper_config() {
  FilterConfig c;
  c.etu_reference_entropy = 0;
  c.outside_crop_nats = 0;
  c.self_calibrate = false;
  c.etu_route_reference = false;
  return c;
}

void FilterConfig::validate() const {
  auto fail = [](const std::string& field, double value, const std::string& constraint) {
    std::ostringstream s;
    s << "filter config: " << field << " = " << value << ": " << constraint;
    throw FilterError(s.str(), ErrorCategory::usage);
  };
  if (width < 8 || width > 4096) fail("width", width, "must be in [8, 4096] cells");
  if (height < 8 || height > 4096) fail("height", height, "must be in [8, 4096] cells");
  if (headings < 4 || headings > 4096) fail("headings", headings, "must be in [4, 4096] bins");
  if (!(mgr_epsilon > 0 && mgr_epsilon < 1)) fail("mgr_epsilon", mgr_epsilon, "must be in (0, 1)");
  if (!(mgr_sigma_m > 0)) fail("mgr_sigma_m", mgr_sigma_m, "must be > 0");
  if (pas_radius < 0 || pas_radius > 64) fail("pas_radius", pas_radius, "must be in [0, 64] cells");
  if (!(relocalization_jump_m > 0)) fail("relocalization_jump_m", relocalization_jump_m, "must be > 0");
  if (!(etu_reference_entropy >= 0 && etu_reference_entropy < 1)) {
    fail("etu_reference_entropy", etu_reference_entropy, "must be in [0, 1) (0: the paper's ETU)");
  }
  if (!(outside_crop_nats >= 0 && outside_crop_nats <= 50)) {
    fail("outside_crop_nats", outside_crop_nats, "must be in [0, 50]");
  }
  if (subbin_half_width < 1 || subbin_half_width >= headings / 2) {
    fail("subbin_half_width", subbin_half_width, "must be in [1, headings / 2)");
  }
  if (!(motion_noise_xy_per_m >= 0)) fail("motion_noise_xy_per_m", motion_noise_xy_per_m, "must be >= 0");
  if (!(motion_noise_deg_per_m >= 0)) fail("motion_noise_deg_per_m", motion_noise_deg_per_m, "must be >= 0");
  if (!(self_calibration_prior_octaves > 0 && self_calibration_prior_octaves <= 16)) {
    fail("self_calibration_prior_octaves", self_calibration_prior_octaves, "must be in (0, 16]");
  }
  if (!(self_calibration_outlier_share >= 0 && self_calibration_outlier_share < 1)) {
    fail("self_calibration_outlier_share", self_calibration_outlier_share, "must be in [0, 1)");
  }
  if (!(self_calibration_hold_below_octaves >= 0 && self_calibration_hold_below_octaves <= 4)) {
    fail("self_calibration_hold_below_octaves", self_calibration_hold_below_octaves, "must be in [0, 4]");
  }
  if (!(self_calibration_hold_above_octaves >= 0 && self_calibration_hold_above_octaves <= 4)) {
    fail("self_calibration_hold_above_octaves", self_calibration_hold_above_octaves, "must be in [0, 4]");
  }
  if (!(self_calibration_hold_follow_octaves >= 0 && self_calibration_hold_follow_octaves <= 10)) {
    fail("self_calibration_hold_follow_octaves", self_calibration_hold_follow_octaves, "must be in [0, 10]");
  }
  if (!(self_calibration_hold_share >= 0 && self_calibration_hold_share <= 1)) {
    fail("self_calibration_hold_share", self_calibration_hold_share, "must be in [0, 1]");
  }
  if (self_calibration_replay_frames < 0 || self_calibration_replay_frames > 64) {
    fail("self_calibration_replay_frames", self_calibration_replay_frames, "must be in [0, 64] frames");
  }
  if (self_calibration_shared_lag != 0 && (self_calibration_shared_lag < 2 || self_calibration_shared_lag > 1000)) {
    fail("self_calibration_shared_lag", self_calibration_shared_lag, "must be 0 or in [2, 1000] frames");
  }
  if (threads < 1 || threads > 256) fail("threads", threads, "must be in [1, 256]");
}

}  // namespace seqloc::filter
