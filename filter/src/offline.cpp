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

std::vector<Pose> offline_poses(const std::vector<OfflineFrame>& frames, const FilterConfig& config, int half_window) {
  config.validate();
  const int n = static_cast<int>(frames.size());
  const int W = config.width, H = config.height, R = config.headings;
  // Each frame's log-likelihood placed in the window, in its own pose space.
  std::vector<BeliefVolume> placed;
  placed.reserve(frames.size());
  std::vector<float> blend;
  for (const auto& f : frames) {
    placed.emplace_back(W, H, R);
    for (int k = 0; k < R; ++k) {
      // Log-likelihoods are sampled (and later warped) linearly: here they are weights to add up.
      detail::sample_slice(f.frame->log_prob.data(), f.frame->bins, f.frame->height, f.frame->width, f.frame->cell_m,
                           f.crop, placed.back().bin_heading_deg(k), W, H, static_cast<float>(-f.frame->log_cells),
                           blend, placed.back().slice(k));
    }
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
        // Motion from s to t: the increments in between, inverted when s is later.
        std::vector<Odometry> steps;
        for (int i = std::min(s, t) + 1; i <= std::max(s, t); ++i) steps.push_back(frames[static_cast<std::size_t>(i)].from_previous);
        Odometry motion = compose(steps);
        if (s > t) motion = invert(motion);
        const float no_info = static_cast<float>(-frames[static_cast<std::size_t>(s)].frame->log_cells);
        detail::warp_volume(*source, warped, motion, no_info, config.threads);
        source = &warped;
      }
      for (std::size_t i = 0; i < sum.size(); ++i) sum.data()[i] += source->data()[i];
    }
    const auto best = std::max_element(sum.data(), sum.data() + sum.size()) - sum.data();
    const auto cells = static_cast<std::ptrdiff_t>(sum.slice_cells());
    const int k = static_cast<int>(best / cells);
    const auto rest = best % cells;
    poses.push_back({static_cast<double>(rest % W), static_cast<double>(rest / W), sum.bin_heading_deg(k)});
  }
  return poses;
}

}  // namespace seqloc::filter
