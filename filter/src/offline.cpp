#include "seqloc/filter/offline.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Core>

#include "internal.hpp"

namespace seqloc::filter {

Odometry compose(const std::vector<Odometry>& increments) {
  // Pose in the start's body frame: x forward, y left, heading counter-clockwise.
  double x = 0, y = 0, yaw = 0;
  for (const auto& o : increments) {
    const double c = std::cos(yaw * M_PI / 180.0), s = std::sin(yaw * M_PI / 180.0);
    x += c * o.forward_m - s * o.left_m;
    y += s * o.forward_m + c * o.left_m;
    yaw += o.yaw_deg;
  }
  return {x, y, yaw};
}

Odometry invert(const Odometry& m) {
  // The start as seen from the end: minus the displacement, rotated into the end's frame.
  const double c = std::cos(m.yaw_deg * M_PI / 180.0), s = std::sin(m.yaw_deg * M_PI / 180.0);
  return {-(c * m.forward_m + s * m.left_m), -(-s * m.forward_m + c * m.left_m), -m.yaw_deg};
}

namespace {

using ArrayMap = Eigen::Map<Eigen::ArrayXf>;
using ConstArrayMap = Eigen::Map<const Eigen::ArrayXf>;

// Frames are placed and warped as probabilities relative to their peak, and only then turned
// into log-likelihoods to add up. Bilinear interpolation of probabilities moves mass between
// cells; of log-probabilities it turns a peak beside log(0) into log(0), so a route of sharp
// volumes off the cell lattice lost every observed cell and its sum peaked where no frame looked.
// A relative probability below the floor (69 nats under the frame's peak) counts as the floor.
constexpr float kRelativeFloor = 1e-30f;

// Frame s's relative probabilities placed in the window, in its own pose space; NaN where its
// crop does not reach (NaN survives interpolation, so a cell half outside stays unobserved).
void place(const OfflineFrame& f, BeliefVolume& out, std::vector<float>& relative, std::vector<float>& blend) {
  const auto& log_prob = f.frame->log_prob;
  relative.resize(log_prob.size());
  ArrayMap(relative.data(), static_cast<Eigen::Index>(relative.size())) =
      (ConstArrayMap(log_prob.data(), static_cast<Eigen::Index>(log_prob.size())) - f.frame->max_log_prob).exp();
  const float unobserved = std::numeric_limits<float>::quiet_NaN();
  for (int k = 0; k < out.headings(); ++k) {
    detail::sample_slice(relative.data(), f.frame->bins, f.frame->height, f.frame->width, f.frame->cell_m, f.crop,
                         out.bin_heading_deg(k), out.width(), out.height(), unobserved, blend, out.slice(k));
  }
}

// Adds frame s's log-likelihood (placed, and warped when s != t) to the sum: its own where it
// observed the cell, log(1/M) - outside_crop_nats where it did not (conventions.md section 6 step 3).
void accumulate(const BeliefVolume& relative, const PreparedFrame& frame, double outside_nats, BeliefVolume& sum) {
  const auto n = static_cast<Eigen::Index>(sum.size());
  const ConstArrayMap p(relative.data(), n);
  const auto no_info = static_cast<float>(-frame.log_cells - outside_nats);
  ArrayMap(sum.data(), n) += p.isNaN().select(no_info, p.max(kRelativeFloor).log() + frame.max_log_prob);
}

// Motion from frame s to frame t: the increments in between, inverted when s is later.
Odometry motion_between(const std::vector<OfflineFrame>& frames, std::size_t s, std::size_t t) {
  std::vector<Odometry> steps;
  for (std::size_t i = std::min(s, t) + 1; i <= std::max(s, t); ++i) steps.push_back(frames[i].from_previous);
  const Odometry m = compose(steps);
  return s > t ? invert(m) : m;
}

// The argmax of the sum over the cells frame t itself observed: its crop is where its pose is
// sought, and elsewhere the sum is made of "no information" terms.
Pose argmax_pose(const BeliefVolume& sum, const BeliefVolume& own) {
  const auto cells = static_cast<std::ptrdiff_t>(sum.slice_cells());
  std::ptrdiff_t best = -1;
  float top = -std::numeric_limits<float>::infinity();
  for (std::ptrdiff_t i = 0; i < static_cast<std::ptrdiff_t>(sum.size()); ++i) {
    if (!std::isnan(own.data()[i]) && (best < 0 || sum.data()[i] > top)) {
      best = i;
      top = sum.data()[i];
    }
  }
  if (best < 0) best = std::max_element(sum.data(), sum.data() + sum.size()) - sum.data();  // no cell observed
  const int k = static_cast<int>(best / cells);
  const auto rest = best % cells;
  const auto u = rest % sum.width(), v = rest / sum.width();  // whole cells
  return {static_cast<double>(u), static_cast<double>(v), sum.bin_heading_deg(k)};
}

// The pose of frame t from the placed frames [s0, s1] (placed(s) gives frame s's placement).
template <class Placed>
Pose pose_from(const std::vector<OfflineFrame>& frames, std::size_t t, std::size_t s0, std::size_t s1, Placed&& placed,
               BeliefVolume& sum, BeliefVolume& warped, const FilterConfig& config) {
  std::fill(sum.data(), sum.data() + sum.size(), 0.0f);
  const float unobserved = std::numeric_limits<float>::quiet_NaN();
  for (std::size_t s = s0; s <= s1; ++s) {
    const BeliefVolume& own = placed(s);
    if (s == t) {
      accumulate(own, *frames[s].frame, config.outside_crop_nats, sum);
    } else {
      detail::warp_volume(own, warped, motion_between(frames, s, t), unobserved, config.threads);
      accumulate(warped, *frames[s].frame, config.outside_crop_nats, sum);
    }
  }
  return argmax_pose(sum, placed(t));
}

}  // namespace

Pose offline_pose_at(const std::vector<OfflineFrame>& frames, std::size_t t, const FilterConfig& config,
                     int half_window) {
  config.validate();
  const int W = config.width, H = config.height, R = config.headings;
  const std::size_t n = frames.size();
  const auto k = static_cast<std::size_t>(half_window);
  const std::size_t s0 = half_window < 0 ? 0 : (t > k ? t - k : 0);
  const std::size_t s1 = half_window < 0 ? n - 1 : std::min(n - 1, t + k);
  BeliefVolume sum(W, H, R), warped(W, H, R), own(W, H, R), other(W, H, R);
  std::vector<float> relative, blend;
  place(frames[t], own, relative, blend);
  return pose_from(
      frames, t, s0, s1,
      [&](std::size_t s) -> const BeliefVolume& {
        if (s == t) return own;
        place(frames[s], other, relative, blend);
        return other;
      },
      sum, warped, config);
}

std::vector<Pose> offline_poses(const std::vector<OfflineFrame>& frames, const FilterConfig& config, int half_window) {
  config.validate();
  const int n = static_cast<int>(frames.size());
  const int W = config.width, H = config.height, R = config.headings;
  // Each frame placed once, shared by every t.
  std::vector<BeliefVolume> placed;
  placed.reserve(frames.size());
  std::vector<float> relative, blend;
  for (const auto& f : frames) {
    placed.emplace_back(W, H, R);
    place(f, placed.back(), relative, blend);
  }
  std::vector<Pose> poses;
  BeliefVolume sum(W, H, R), warped(W, H, R);
  for (int t = 0; t < n; ++t) {
    const int s0 = half_window < 0 ? 0 : std::max(0, t - half_window);
    const int s1 = half_window < 0 ? n - 1 : std::min(n - 1, t + half_window);
    poses.push_back(pose_from(
        frames, static_cast<std::size_t>(t), static_cast<std::size_t>(s0), static_cast<std::size_t>(s1),
        [&](std::size_t s) -> const BeliefVolume& { return placed[s]; }, sum, warped, config));
  }
  return poses;
}

}  // namespace seqloc::filter
