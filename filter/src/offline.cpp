#include "seqloc/filter/offline.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

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

// Frame s's log-likelihood placed in the window, in its own pose space.
void place(const OfflineFrame& f, BeliefVolume& out, std::vector<float>& blend) {
  for (int k = 0; k < out.headings(); ++k) {
    // Log-likelihoods are sampled (and later warped) linearly: here they are weights to add up.
    detail::sample_slice(f.frame->log_prob.data(), f.frame->bins, f.frame->height, f.frame->width, f.frame->cell_m,
                         f.crop, out.bin_heading_deg(k), out.width(), out.height(),
                         static_cast<float>(-f.frame->log_cells), blend, out.slice(k));
  }
}

// Motion from frame s to frame t: the increments in between, inverted when s is later.
Odometry motion_between(const std::vector<OfflineFrame>& frames, std::size_t s, std::size_t t) {
  std::vector<Odometry> steps;
  for (std::size_t i = std::min(s, t) + 1; i <= std::max(s, t); ++i) steps.push_back(frames[i].from_previous);
  const Odometry m = compose(steps);
  return s > t ? invert(m) : m;
}

Pose argmax_pose(const BeliefVolume& sum) {
  const auto best = std::max_element(sum.data(), sum.data() + sum.size()) - sum.data();
  const auto cells = static_cast<std::ptrdiff_t>(sum.slice_cells());
  const int k = static_cast<int>(best / cells);
  const auto rest = best % cells;
  const auto u = rest % sum.width(), v = rest / sum.width();  // whole cells
  return {static_cast<double>(u), static_cast<double>(v), sum.bin_heading_deg(k)};
}

}  // namespace

Pose offline_pose_at(const std::vector<OfflineFrame>& frames, std::size_t t, const FilterConfig& config,
                     int half_window) {
  config.validate();
  const int W = config.width, H = config.height, R = config.headings;
  const std::size_t n = frames.size();
  const std::size_t s0 = half_window < 0 ? 0 : (t > static_cast<std::size_t>(half_window) ? t - static_cast<std::size_t>(half_window) : 0);
  const std::size_t s1 = half_window < 0 ? n - 1 : std::min(n - 1, t + static_cast<std::size_t>(half_window));
  BeliefVolume sum(W, H, R), placed(W, H, R), warped(W, H, R);
  std::fill(sum.data(), sum.data() + sum.size(), 0.0f);
  std::vector<float> blend;
  for (std::size_t s = s0; s <= s1; ++s) {
    place(frames[s], placed, blend);
    const BeliefVolume* source = &placed;
    if (s != t) {
      const auto no_info = static_cast<float>(-frames[s].frame->log_cells);
      detail::warp_volume(placed, warped, motion_between(frames, s, t), no_info, config.threads);
      source = &warped;
    }
    for (std::size_t i = 0; i < sum.size(); ++i) sum.data()[i] += source->data()[i];
  }
  return argmax_pose(sum);
}

std::vector<Pose> offline_poses(const std::vector<OfflineFrame>& frames, const FilterConfig& config, int half_window) {
  config.validate();
  const int n = static_cast<int>(frames.size());
  const int W = config.width, H = config.height, R = config.headings;
  // Each frame's log-likelihood placed once, shared by every t.
  std::vector<BeliefVolume> placed;
  placed.reserve(frames.size());
  std::vector<float> blend;
  for (const auto& f : frames) {
    placed.emplace_back(W, H, R);
    place(f, placed.back(), blend);
  }
  std::vector<Pose> poses;
  BeliefVolume sum(W, H, R), warped(W, H, R);
  for (int t = 0; t < n; ++t) {
    std::fill(sum.data(), sum.data() + sum.size(), 0.0f);
    const int s0 = half_window < 0 ? 0 : std::max(0, t - half_window);
    const int s1 = half_window < 0 ? n - 1 : std::min(n - 1, t + half_window);
    for (int s = s0; s <= s1; ++s) {
      const BeliefVolume* source = &placed[static_cast<std::size_t>(s)];
      if (s != t) {
        const auto no_info = static_cast<float>(-frames[static_cast<std::size_t>(s)].frame->log_cells);
        detail::warp_volume(*source, warped,
                            motion_between(frames, static_cast<std::size_t>(s), static_cast<std::size_t>(t)), no_info,
                            config.threads);
        source = &warped;
      }
      for (std::size_t i = 0; i < sum.size(); ++i) sum.data()[i] += source->data()[i];
    }
    poses.push_back(argmax_pose(sum));
  }
  return poses;
}

}  // namespace seqloc::filter
