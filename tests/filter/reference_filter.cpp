#include "filter/reference_filter.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include "seqloc/core/angles.hpp"

namespace seqloc::filter::test {
namespace {

constexpr double kPi = 3.14159265358979323846;

// log(sum_i w_i exp(l_i)) over the terms of positive weight, computed stably.
double weighted_log_sum_exp(const std::vector<std::pair<double, double>>& terms) {
  double m = -std::numeric_limits<double>::infinity();
  for (const auto& [l, w] : terms)
    if (w > 0) m = std::max(m, l);
  double sum = 0;
  for (const auto& [l, w] : terms)
    if (w > 0) sum += w * std::exp(l - m);
  return m + std::log(sum);
}

}  // namespace

ReferenceFilter::ReferenceFilter(const FilterConfig& config)
    : c_(config), b_(static_cast<std::size_t>(config.width) * config.height * config.headings) {
  c_.validate();
  reset_uniform();
}

void ReferenceFilter::reset_uniform() {
  std::fill(b_.begin(), b_.end(), -std::log(static_cast<double>(b_.size())));
  first_ = true;
  entropies_.clear();
}

void ReferenceFilter::reset_gaussian(double u0, double v0, double sigma_m) {
  const double sigma = sigma_m / 0.5;
  double sum = 0;
  for (int v = 0; v < c_.height; ++v)
    for (int u = 0; u < c_.width; ++u) sum += std::exp(-((u - u0) * (u - u0) + (v - v0) * (v - v0)) / (2 * sigma * sigma));
  for (int k = 0; k < c_.headings; ++k)
    for (int v = 0; v < c_.height; ++v)
      for (int u = 0; u < c_.width; ++u) {
        const double g = std::exp(-((u - u0) * (u - u0) + (v - v0) * (v - v0)) / (2 * sigma * sigma));
        b_[index(u, v, k)] = std::log(g / sum / c_.headings);
      }
  first_ = true;
  entropies_.clear();
}

FrameResult ReferenceFilter::step(const FrameVolume& volume, const CropPose& crop, const Odometry& odo,
                                  std::span<const float> road_distance_m, const std::optional<GpsFix>& gps,
                                  double volume_power) {
  // 1. Predict (not on the first frame after a reset).
  if (!first_) predict(odo);
  // 2. ETU: the frame's log-probabilities raised to the power and normalized, and its weight.
  FrameResult r;
  r.volume_power = volume_power;
  const std::vector<double> logp = weigh(volume, r);
  // 3. Update with the weighted frame sampled into the window, and the GPS term.
  update(volume, logp, crop, gps, r.etu_weight);
  // 4. MGR.
  if (c_.mgr) blend_road_prior(road_distance_m);
  // 5. The argmax, and PAS around it.
  estimate(r);
  first_ = false;
  return r;
}

void ReferenceFilter::predict(const Odometry& odo) {
  const int W = c_.width, H = c_.height, R = c_.headings;
  // b_hat(x, th) = log of the probability-domain interpolation: bilinear in space
  //    (each source bin j translated by the odometry's displacement d(th_j)), linear between the
  //    two source bins around th + yaw; sources outside the window count as the window minimum.
  const double window_min = *std::min_element(b_.begin(), b_.end());
  std::vector<double> hat(b_.size());
  for (int k = 0; k < R; ++k) {
    const double p = k + odo.yaw_deg * R / 360.0;
    const double fp = std::floor(p);
    const double a = p - fp;
    const int j0 = static_cast<int>(((static_cast<long long>(fp) % R) + R) % R), j1 = (j0 + 1) % R;
    for (int v = 0; v < H; ++v)
      for (int u = 0; u < W; ++u) {
        std::vector<std::pair<double, double>> terms;  // (log value, weight)
        for (int side = 0; side < 2; ++side) {
          const int j = side == 0 ? j0 : j1;
          const double wj = side == 0 ? 1 - a : a;
          if (wj == 0) continue;
          const double h = j * 360.0 / R * kPi / 180.0;
          double du = (odo.forward_m * std::sin(h) - odo.left_m * std::cos(h)) / 0.5;
          double dv = -(odo.forward_m * std::cos(h) + odo.left_m * std::sin(h)) / 0.5;
          if (std::abs(du - std::round(du)) < 1e-9) du = std::round(du);
          if (std::abs(dv - std::round(dv)) < 1e-9) dv = std::round(dv);
          const double x = u - du, y = v - dv;
          if (x < 0 || y < 0 || x > W - 1 || y > H - 1) {
            terms.emplace_back(window_min, wj);
            continue;
          }
          const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
          const int x1 = std::min(x0 + 1, W - 1), y1 = std::min(y0 + 1, H - 1);
          const double ax = x - x0, ay = y - y0;
          terms.emplace_back(b_[index(x0, y0, j)], wj * (1 - ax) * (1 - ay));
          terms.emplace_back(b_[index(x1, y0, j)], wj * ax * (1 - ay));
          terms.emplace_back(b_[index(x0, y1, j)], wj * (1 - ax) * ay);
          terms.emplace_back(b_[index(x1, y1, j)], wj * ax * ay);
        }
        hat[index(u, v, k)] = weighted_log_sum_exp(terms);
      }
  }
  b_ = hat;
}

std::vector<double> ReferenceFilter::weigh(const FrameVolume& volume, FrameResult& r) {
  // The frame raised to the given power (self-calibration's), normalized over its own M cells,
  // its normalized entropy and weight.
  const double volume_power = r.volume_power;
  const int vh = volume.height, vw = volume.width, vn = volume.bins;
  const std::size_t m_cells = static_cast<std::size_t>(vh) * vw * vn;
  std::vector<double> logp(m_cells);  // [bin][v][u]
  for (int v = 0; v < vh; ++v)
    for (int u = 0; u < vw; ++u)
      for (int j = 0; j < vn; ++j) {
        const std::size_t i = (static_cast<std::size_t>(v) * vw + u) * vn + j;
        double x = volume.type == VolumeType::float32 ? static_cast<const float*>(volume.data)[i]
                                                     : half_to_float(static_cast<const std::uint16_t*>(volume.data)[i]);
        if (volume.values == VolumeValues::prob) x = x > 0 ? std::log(x) : -std::numeric_limits<double>::infinity();
        if (std::isinf(x)) x = kLogZero;  // the filter's stand-in for log(0)
        logp[(static_cast<std::size_t>(j) * vh + v) * vw + u] = x;
      }
  const double log_m = std::log(static_cast<double>(m_cells));
  // Normalizes `values` raised to `power` in place; returns the normalized entropy.
  const auto normalize = [log_m](std::vector<double>& values, double power) {
    double max = -std::numeric_limits<double>::infinity();
    for (double& x : values) {
      if (x > kLogZero) x *= power;
      max = std::max(max, x);
    }
    double sum = 0;
    for (double x : values) sum += std::exp(x - max);
    const double lse_frame = max + std::log(sum);
    double entropy = 0;
    for (double& x : values) {
      if (x <= kLogZero) continue;
      x -= lse_frame;
      entropy -= std::exp(x) * x;
    }
    return std::clamp(entropy / log_m, 0.0, 1.0);
  };
  std::vector<double> given = logp;
  const double h_given = normalize(given, 1.0);
  const double h_hat = normalize(logp, volume_power);
  // Written out here, not by etu_weight(), so the reference states the rule itself: relative to
  // the median of the route's given entropies (the upper one of an even count), or to the
  // configured reference, or the paper's 1 - H.
  double w = 1;
  if (c_.etu && c_.etu_route_reference) {
    entropies_.push_back(h_given);
    std::vector<double> sorted(entropies_.end() - static_cast<std::ptrdiff_t>(std::min<std::size_t>(entropies_.size(), 256)),
                               entropies_.end());
    std::sort(sorted.begin(), sorted.end());
    const double h_ref = std::min(sorted[sorted.size() / 2], 1.0 - 1e-9);
    w = h_ref > 0 ? std::clamp((1 - h_given) / (1 - h_ref), 1e-3, 1.0) : std::max(1 - h_given, 1e-3);
  } else if (c_.etu) {
    w = c_.etu_reference_entropy > 0 ? std::clamp((1 - h_hat) / (1 - c_.etu_reference_entropy), 1e-3, 1.0)
                                     : std::max(1 - h_hat, 1e-3);
  }
  r.frame_entropy = h_hat;
  r.etu_weight = w;
  return logp;
}

void ReferenceFilter::update(const FrameVolume& volume, const std::vector<double>& logp, const CropPose& crop,
                             const std::optional<GpsFix>& gps, double w) {
  const int W = c_.width, H = c_.height, R = c_.headings;
  const int vh = volume.height, vw = volume.width, vn = volume.bins;
  const double log_m = std::log(static_cast<double>(static_cast<std::size_t>(vh) * vw * vn));
  // b = log_softmax(w log p + b_hat). The tempered likelihood p^w is sampled at every
  //    window cell and bin by linear interpolation of p^w (bilinear in space, linear between the
  //    two bins around the crop's heading), computed here as a log-sum-exp of the neighbours.
  const double rot = crop.rotation_deg * kPi / 180.0;
  std::vector<double> val(b_.size());
  for (int k = 0; k < R; ++k) {
    const double p = core::wrap360(k * 360.0 / R - crop.rotation_deg) * vn / 360.0;
    const int j0 = static_cast<int>(std::floor(p)) % vn, j1 = (j0 + 1) % vn;
    const double a = p - std::floor(p);
    for (int v = 0; v < H; ++v)
      for (int u = 0; u < W; ++u) {
        const double east = (u - crop.centre_u) * 0.5, north = -(v - crop.centre_v) * 0.5;
        // The crop's axes are the window's turned clockwise by the rotation.
        const double ce = east * std::cos(rot) - north * std::sin(rot);
        const double cn = east * std::sin(rot) + north * std::cos(rot);
        const double x = ce / volume.cell_m + (vw - 1) / 2.0, y = -cn / volume.cell_m + (vh - 1) / 2.0;
        double l = w * (-log_m - c_.outside_crop_nats);  // outside the crop
        if (x >= 0 && y >= 0 && x <= vw - 1 && y <= vh - 1) {
          const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
          const int x1 = std::min(x0 + 1, vw - 1), y1 = std::min(y0 + 1, vh - 1);
          const double ax = x - x0, ay = y - y0;
          std::vector<std::pair<double, double>> terms;  // (w log p, weight)
          for (int side = 0; side < 2; ++side) {
            const int j = side == 0 ? j0 : j1;
            const double wj = side == 0 ? 1 - a : a;
            auto at = [&](int xx, int yy) { return w * logp[(static_cast<std::size_t>(j) * vh + yy) * vw + xx]; };
            terms.emplace_back(at(x0, y0), wj * (1 - ax) * (1 - ay));
            terms.emplace_back(at(x1, y0), wj * ax * (1 - ay));
            terms.emplace_back(at(x0, y1), wj * (1 - ax) * ay);
            terms.emplace_back(at(x1, y1), wj * ax * ay);
          }
          l = weighted_log_sum_exp(terms);
        }
        double g = 0;
        if (c_.gps_prior && gps) {
          const double du = (u - gps->u) * 0.5, dv = (v - gps->v) * 0.5;
          g = -(du * du + dv * dv) / (2 * gps->sigma_m * gps->sigma_m);
        }
        val[index(u, v, k)] = l + b_[index(u, v, k)] + g;
      }
  }
  const double vmax = *std::max_element(val.begin(), val.end());
  double vsum = 0;
  for (double x : val) vsum += std::exp(x - vmax);
  const double lse = vmax + std::log(vsum);
  for (std::size_t i = 0; i < b_.size(); ++i) b_[i] = val[i] - lse;
}

void ReferenceFilter::blend_road_prior(std::span<const float> road_distance_m) {
  // b <- log((1 - eps) exp(b) + eps q), q = (0.9 g / Z + 0.1 / M_xy) / R.
  const int W = c_.width, H = c_.height, R = c_.headings;
  const std::size_t mxy = static_cast<std::size_t>(W) * H;
  if (road_distance_m.size() != mxy) throw FilterError("reference: the road-distance window is not W x H", ErrorCategory::usage);
  std::vector<double> g(mxy);
  double z = 0;
  for (std::size_t i = 0; i < mxy; ++i) {
    const double d = road_distance_m[i];
    g[i] = std::exp(-d * d / (2 * c_.mgr_sigma_m * c_.mgr_sigma_m));
    z += g[i];
  }
  for (int k = 0; k < R; ++k)
    for (std::size_t i = 0; i < mxy; ++i) {
      const double q = (0.9 * g[i] / z + 0.1 / static_cast<double>(mxy)) / R;
      double& b = b_[static_cast<std::size_t>(k) * mxy + i];
      b = std::log((1 - c_.mgr_epsilon) * std::exp(b) + c_.mgr_epsilon * q);
    }
}

void ReferenceFilter::estimate(FrameResult& r) const {
  // The argmax, and PAS around it.
  const int W = c_.width, H = c_.height, R = c_.headings;
  int bu = 0, bv = 0, bk = 0;
  double best = -std::numeric_limits<double>::infinity();
  for (int k = 0; k < R; ++k)
    for (int v = 0; v < H; ++v)
      for (int u = 0; u < W; ++u)
        if (b_[index(u, v, k)] > best) {
          best = b_[index(u, v, k)];
          bu = u;
          bv = v;
          bk = k;
        }
  r.peak_log_belief = static_cast<float>(best);
  r.argmax = {static_cast<double>(bu), static_cast<double>(bv), bk * 360.0 / R};
  r.pose = r.argmax;
  if (c_.pas) {
    double sm = 0, su = 0, sv = 0;
    for (int v = bv - c_.pas_radius; v <= bv + c_.pas_radius; ++v)
      for (int u = bu - c_.pas_radius; u <= bu + c_.pas_radius; ++u) {
        if (u < 0 || v < 0 || u >= W || v >= H) continue;
        double m = 0;
        for (int k = 0; k < R; ++k) m += std::exp(b_[index(u, v, k)]);
        sm += m;
        su += m * u;
        sv += m * v;
      }
    r.pose.u = su / sm;
    r.pose.v = sv / sm;
  }
}


}  // namespace seqloc::filter::test
