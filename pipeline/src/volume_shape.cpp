#include "seqloc/pipeline/volume_shape.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

#include "seqloc/core/angles.hpp"
#include "seqloc/core/flat_index.hpp"

namespace seqloc::pipeline {

std::vector<double> position_marginal(const filter::PreparedFrame& frame) {
  const std::size_t slice = static_cast<std::size_t>(frame.height) * static_cast<std::size_t>(frame.width);
  std::vector<double> marginal(slice, 0.0);
  for (int k = 0; k < frame.bins; ++k) {
    const float* s = frame.log_prob.data() + static_cast<std::size_t>(k) * slice;
    for (std::size_t i = 0; i < slice; ++i) marginal[i] += std::exp(static_cast<double>(s[i]));
  }
  return marginal;
}

std::vector<float> window_marginal(const filter::PreparedFrame& frame, const filter::CropPose& crop, int width,
                                   int height) {
  std::vector<double> placed(static_cast<std::size_t>(width) * static_cast<std::size_t>(height), 0.0);
  const std::vector<double> own = position_marginal(frame);
  for (int v = 0; v < frame.height; ++v) {
    for (int u = 0; u < frame.width; ++u) {
      const filter::Pose cell = filter::volume_cell_pose(frame, crop, v, u, 0);
      const auto wu = std::lround(cell.u), wv = std::lround(cell.v);
      if (wu >= 0 && wu < width && wv >= 0 && wv < height) {
        placed[static_cast<std::size_t>(wv * width + wu)] += own[core::flat(v, u, frame.width)];
      }
    }
  }
  return {placed.begin(), placed.end()};
}

VolumeShape volume_shape(const filter::PreparedFrame& frame, double heading_deg) {
  const std::vector<double> marginal = position_marginal(frame);
  const std::size_t slice = marginal.size();
  std::vector<double> sorted = marginal;
  const auto tenth = sorted.begin() + static_cast<std::ptrdiff_t>(slice / 10);
  std::nth_element(sorted.begin(), tenth, sorted.end());
  const double base = *tenth;
  // Moments in metres: east = u, north = -v.
  double w_sum = 0, e_sum = 0, n_sum = 0, ee = 0, nn = 0, en = 0;
  for (int v = 0; v < frame.height; ++v) {
    for (int u = 0; u < frame.width; ++u) {
      const double w = marginal[core::flat(v, u, frame.width)] - base;
      if (w <= 0) continue;
      const double e = u * frame.cell_m, n = -v * frame.cell_m;
      w_sum += w;
      e_sum += w * e;
      n_sum += w * n;
      ee += w * e * e;
      nn += w * n * n;
      en += w * e * n;
    }
  }
  VolumeShape shape;
  if (!(w_sum > 0)) return shape;  // a flat volume has no shape
  const double me = e_sum / w_sum, mn = n_sum / w_sum;
  const double cee = ee / w_sum - me * me, cnn = nn / w_sum - mn * mn, cen = en / w_sum - me * mn;
  // Eigenvalues of [[cee, cen], [cen, cnn]] and the major axis's direction.
  const double half_trace = (cee + cnn) / 2, root = std::hypot((cee - cnn) / 2, cen);
  const double l1 = half_trace + root, l2 = std::max(half_trace - root, 0.0);
  shape.major_sigma_m = std::sqrt(std::max(l1, 0.0));
  shape.minor_sigma_m = std::sqrt(l2);
  shape.elongation = l2 > 0 ? std::sqrt(l1 / l2) : (l1 > 0 ? INFINITY : 1.0);
  // Major axis angle from the east axis, then as a heading (clockwise from north).
  const double axis_from_east = 0.5 * std::atan2(2 * cen, cee - cnn) * core::kRadToDeg;
  const double axis_heading = 90.0 - axis_from_east;
  double d = std::fmod(std::abs(axis_heading - heading_deg), 180.0);
  if (d > 90) d = 180 - d;
  shape.axis_to_heading_deg = d;
  return shape;
}

}  // namespace seqloc::pipeline
