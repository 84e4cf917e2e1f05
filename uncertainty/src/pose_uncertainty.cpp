// A pose's uncertainty from its belief (pose_uncertainty.hpp).

#include "seqloc/uncertainty/pose_uncertainty.hpp"

#include <algorithm>
#include <cmath>
#include <optional>
#include <vector>

#include <Eigen/Core>

#include "seqloc/core/angles.hpp"
#include "seqloc/core/thread_pool.hpp"
#include "seqloc/core/units.hpp"

namespace seqloc::uncertainty {
namespace {

using core::kCellM;

// The position marginal (W x H) and the heading marginal (R), in one pass over the belief, in
// blocks of a fixed number of cells (in parallel; each block reads every slice's stretch of it
// whole): cells summed over headings in float (SIMD; 256 terms of at most 1 lose under 1e-5
// relative), each block's heading sums kept apart and added in block order in double, so that
// the sums do not depend on the number of threads.
void marginals(const BeliefVolume& belief, int threads, std::vector<double>& position, std::vector<double>& heading) {
  const int r = belief.headings();
  const std::size_t n = belief.slice_cells();
  constexpr std::size_t kBlock = 16384;
  const auto blocks = static_cast<int>((n + kBlock - 1) / kBlock);
  std::vector<float> cells(n, 0.0f);
  std::vector<double> by_block(static_cast<std::size_t>(blocks) * static_cast<std::size_t>(r));
  core::parallel_chunks(blocks, threads, [&](int b0, int b1, int) {
    for (int b = b0; b < b1; ++b) {
      const std::size_t start = static_cast<std::size_t>(b) * kBlock, len = std::min(kBlock, n - start);
      Eigen::Map<Eigen::ArrayXf> acc(cells.data() + start, static_cast<Eigen::Index>(len));
      for (int k = 0; k < r; ++k) {
        const Eigen::Map<const Eigen::ArrayXf> part(belief.slice(k) + start, static_cast<Eigen::Index>(len));
        acc += part;
        by_block[static_cast<std::size_t>(b) * r + k] = part.sum();
      }
    }
  });
  position.assign(cells.begin(), cells.end());
  heading.assign(static_cast<std::size_t>(r), 0.0);
  for (int b = 0; b < blocks; ++b)
    for (int k = 0; k < r; ++k) heading[static_cast<std::size_t>(k)] += by_block[static_cast<std::size_t>(b) * r + k];
}

// The mass of `position` within `radius_m` of window cell (u0, v0).
double mass_within(const std::vector<double>& position, int width, int height, double u0, double v0, double radius_m) {
  const double radius_cells = radius_m / kCellM;
  double sum = 0;
  const int vlo = std::max(0, static_cast<int>(std::floor(v0 - radius_cells)));
  const int vhi = std::min(height - 1, static_cast<int>(std::ceil(v0 + radius_cells)));
  const int ulo = std::max(0, static_cast<int>(std::floor(u0 - radius_cells)));
  const int uhi = std::min(width - 1, static_cast<int>(std::ceil(u0 + radius_cells)));
  for (int v = vlo; v <= vhi; ++v)
    for (int u = ulo; u <= uhi; ++u) {
      const double du = u - u0, dv = v - v0;
      if (du * du + dv * dv <= radius_cells * radius_cells) sum += position[static_cast<std::size_t>(v) * width + u];
    }
  return sum;
}

// Whether the marginal falls below half of the lower end's value somewhere on the segment between
// cells a and b (a valley: two places, not one ridge along a road).
bool valley_between(const std::vector<double>& position, int width, int ua, int va, int ub, int vb) {
  const double low = 0.5 * std::min(position[static_cast<std::size_t>(va) * width + ua],
                                    position[static_cast<std::size_t>(vb) * width + ub]);
  const int steps = std::max(std::abs(ub - ua), std::abs(vb - va));
  for (int i = 1; i < steps; ++i) {
    const double t = static_cast<double>(i) / steps;
    const auto u = static_cast<int>(std::lround(ua + t * (ub - ua)));
    const auto v = static_cast<int>(std::lround(va + t * (vb - va)));
    if (position[static_cast<std::size_t>(v) * width + u] < low) return true;
  }
  return false;
}

struct Cell {
  double mass;
  int u, v;
};

// The second mode: among the marginal's local maxima (over their 3 x 3 cells) farther than
// kSecondModeMinDistanceM from (u0, v0), the largest with a valley between it and the marginal's
// peak near the estimate.
std::optional<Cell> second_mode(const std::vector<double>& position, int w, int h, double u0, double v0) {
  const double far_cells = kSecondModeMinDistanceM / kCellM;
  std::vector<Cell> maxima;
  Cell home{-1, static_cast<int>(std::lround(u0)), static_cast<int>(std::lround(v0))};
  home.u = std::clamp(home.u, 0, w - 1);
  home.v = std::clamp(home.v, 0, h - 1);
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) {
      const double m = position[static_cast<std::size_t>(v) * w + u];
      const double du = u - u0, dv = v - v0;
      if (du * du + dv * dv <= far_cells * far_cells) {
        if (m > home.mass) home = {m, u, v};
        continue;
      }
      bool peak = m > 0;
      for (int y = std::max(0, v - 1); y <= std::min(h - 1, v + 1) && peak; ++y)
        for (int x = std::max(0, u - 1); x <= std::min(w - 1, u + 1) && peak; ++x)
          peak = position[static_cast<std::size_t>(y) * w + x] <= m;
      if (peak) maxima.push_back({m, u, v});
    }
  std::sort(maxima.begin(), maxima.end(), [](const Cell& a, const Cell& b) { return a.mass > b.mass; });
  constexpr std::size_t kTried = 16;  // a ridge's plateau has a few; the first separated one decides
  for (std::size_t i = 0; i < std::min(kTried, maxima.size()); ++i) {
    if (valley_between(position, w, home.u, home.v, maxima[i].u, maxima[i].v)) return maxima[i];
  }
  return std::nullopt;
}

}  // namespace

PoseUncertainty pose_uncertainty(const BeliefVolume& belief, const Pose& estimate, int threads) {
  std::vector<double> position, heading;
  marginals(belief, threads, position, heading);
  const int w = belief.width(), h = belief.height();
  double total = 0, see = 0, sen = 0, snn = 0;
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u) {
      const double m = position[static_cast<std::size_t>(v) * w + u];
      const double e = (u - estimate.u) * kCellM, n = -(v - estimate.v) * kCellM;
      total += m;
      see += m * e * e;
      sen += m * e * n;
      snn += m * n * n;
    }
  PoseUncertainty out;
  if (!(total > 0)) return out;
  // A cell's own extent: the position is uniform within the estimate's cell (variance cell^2 / 12
  // on each axis), so that a belief on one cell does not claim to know the position exactly.
  const double quantization = kCellM * kCellM / 12;
  out.cov_ee_m2 = see / total + quantization;
  out.cov_en_m2 = sen / total;
  out.cov_nn_m2 = snn / total + quantization;
  out.mass_within_5m = mass_within(position, w, h, estimate.u, estimate.v, kNearM) / total;
  if (const auto other = second_mode(position, w, h, estimate.u, estimate.v)) {
    out.second_mode_share = mass_within(position, w, h, other->u, other->v, kNearM) / total;
    out.second_mode_distance_m = std::hypot(other->u - estimate.u, other->v - estimate.v) * kCellM;
    out.multimodal = out.second_mode_share >= kSecondModeShare;
  }
  double heading_total = 0, heading_var = 0;
  for (int k = 0; k < belief.headings(); ++k) {
    const double d = core::wrap180(belief.bin_heading_deg(k) - estimate.heading_deg);
    heading_total += heading[static_cast<std::size_t>(k)];
    heading_var += heading[static_cast<std::size_t>(k)] * d * d;
  }
  // A bin's own width likewise (uniform within it).
  const double bin_deg = 360.0 / belief.headings();
  out.heading_sd_deg = std::sqrt(heading_var / heading_total + bin_deg * bin_deg / 12);
  return out;
}

Ellipse covariance_ellipse(double cov_ee, double cov_en, double cov_nn, double p) {
  const double mean = (cov_ee + cov_nn) / 2, half = std::hypot((cov_ee - cov_nn) / 2, cov_en);
  const double major = std::max(mean + half, 0.0), minor = std::max(mean - half, 0.0);
  const double scale = core::chi2_2(p);
  // The major axis' direction (east, north): an eigenvector of [[ee, en], [en, nn]] for `major`.
  double e = cov_en, n = major - cov_ee;
  if (std::abs(e) < 1e-300 && std::abs(n) < 1e-300) {
    e = cov_ee >= cov_nn ? 1.0 : 0.0;
    n = cov_ee >= cov_nn ? 0.0 : 1.0;
  }
  double bearing = std::atan2(e, n) / core::kDegToRad;
  bearing = std::fmod(bearing + 360.0, 180.0);
  return {std::sqrt(scale * major), std::sqrt(scale * minor), bearing};
}

}  // namespace seqloc::uncertainty
