#include "seqloc/filter/seqloc_filter.hpp"

#include <algorithm>
#include <cassert>
#include <cmath>
#include <limits>
#include <sstream>

#include <Eigen/Core>

#include "internal.hpp"
#include "parallel.hpp"

namespace seqloc::filter {
namespace {

constexpr double kCellM = 0.5;
constexpr double kDegToRad = M_PI / 180.0;

using ArrayMap = Eigen::Map<Eigen::ArrayXf>;
using ConstArrayMap = Eigen::Map<const Eigen::ArrayXf>;

/// dst(u, v) = src sampled bilinearly at (u + ou, v + ov); `fill` where that point lies outside
/// the source [0, sw - 1] x [0, sh - 1]. At the last column or row the missing neighbour has
/// weight 0 and is read clamped.
void translate(const float* src, int sw, int sh, float* dst, int dw, int dh, double ou, double ov, float fill) {
  const double fu = std::floor(ou), fv = std::floor(ov);
  const auto au = static_cast<float>(ou - fu), av = static_cast<float>(ov - fv);
  const int iu = static_cast<int>(fu), iv = static_cast<int>(fv);
  // Valid u: 0 <= u + ou <= sw - 1.
  const int u_lo = std::max(0, static_cast<int>(std::ceil(-ou)));
  const int u_hi = std::min(dw - 1, static_cast<int>(std::floor(sw - 1 - ou)));
  const int v_lo = std::max(0, static_cast<int>(std::ceil(-ov)));
  const int v_hi = std::min(dh - 1, static_cast<int>(std::floor(sh - 1 - ov)));
  const float w00 = (1 - au) * (1 - av), w01 = au * (1 - av), w10 = (1 - au) * av, w11 = au * av;
  for (int v = 0; v < dh; ++v) {
    float* out = dst + static_cast<std::size_t>(v) * dw;
    if (v < v_lo || v > v_hi || u_lo > u_hi) {
      std::fill(out, out + dw, fill);
      continue;
    }
    const int r0 = v + iv, r1 = std::min(r0 + 1, sh - 1);
    const float* a = src + static_cast<std::size_t>(r0) * sw + iu;
    const float* b = src + static_cast<std::size_t>(r1) * sw + iu;
    std::fill(out, out + u_lo, fill);
    // Columns whose right neighbour exists; the last valid one may need the clamp.
    const int u_inner = std::min(u_hi, sw - 2 - iu);
    for (int u = u_lo; u <= u_inner; ++u) out[u] = w00 * a[u] + w01 * a[u + 1] + w10 * b[u] + w11 * b[u + 1];
    for (int u = std::max(u_lo, u_inner + 1); u <= u_hi; ++u) out[u] = w00 * a[u] + w10 * b[u] + w01 * a[u] + w11 * b[u];
    std::fill(out + u_hi + 1, out + dw, fill);
  }
}

double wrap_degrees(double d) {
  d = std::fmod(d, 360.0);
  return d < 0 ? d + 360.0 : d;
}

}  // namespace

namespace detail {

void displacement_cells(const Odometry& o, double heading_deg, double& du, double& dv) {
  const double h = heading_deg * kDegToRad;
  const double east = o.forward_m * std::sin(h) - o.left_m * std::cos(h);
  const double north = o.forward_m * std::cos(h) + o.left_m * std::sin(h);
  du = east / kCellM;
  dv = -north / kCellM;
  // sin and cos of multiples of 90 degrees are not exactly 0 in floating point; a move that is
  // a whole number of cells up to 1e-9 is taken as one, so that it translates without blurring.
  if (std::abs(du - std::round(du)) < 1e-9) du = std::round(du);
  if (std::abs(dv - std::round(dv)) < 1e-9) dv = std::round(dv);
}

}  // namespace detail

using detail::displacement_cells;

// ---------------------------------------------------------------------------------------------
// Frame intake

PreparedFrame prepare_frame(const FrameVolume& volume, int window_headings) {
  std::ostringstream where;
  where << "volume of shape (" << volume.height << ", " << volume.width << ", " << volume.bins << ")";
  if (volume.data == nullptr || volume.height <= 0 || volume.width <= 0 || volume.bins <= 0) {
    throw FilterError(where.str() + ": empty volume");
  }
  if (window_headings % volume.bins != 0 && volume.bins % window_headings != 0) {
    throw FilterError(where.str() + ": " + std::to_string(volume.bins) +
                      " heading bins neither divide nor are a multiple of the filter's " +
                      std::to_string(window_headings));
  }
  if (!(volume.cell_m > 0)) throw FilterError(where.str() + ": cell size must be > 0");
  PreparedFrame f;
  f.height = volume.height;
  f.width = volume.width;
  f.bins = volume.bins;
  f.cell_m = volume.cell_m;
  const std::size_t cells = static_cast<std::size_t>(volume.height) * volume.width * volume.bins;
  f.log_cells = std::log(static_cast<double>(cells));
  f.log_prob.resize(cells);
  // Convert to log values, heading-major, checking every value.
  const bool is_prob = volume.values == VolumeValues::prob;
  double max = -std::numeric_limits<double>::infinity();
  std::size_t max_index = 0;
  for (std::size_t i = 0; i < cells; ++i) {
    const float raw = volume.type == VolumeType::float32 ? static_cast<const float*>(volume.data)[i]
                                                         : half_to_float(static_cast<const std::uint16_t*>(volume.data)[i]);
    const std::size_t bin = i % static_cast<std::size_t>(volume.bins);
    const std::size_t pixel = i / static_cast<std::size_t>(volume.bins);
    if (std::isnan(raw)) throw FilterError(where.str() + ": NaN at cell " + std::to_string(i));
    float value;
    if (is_prob) {
      if (raw < 0 || std::isinf(raw)) {
        throw FilterError(where.str() + ": probability " + std::to_string(raw) + " at cell " + std::to_string(i));
      }
      value = raw > 0 ? std::log(raw) : kLogZero;
    } else {
      if (raw == std::numeric_limits<float>::infinity()) {
        throw FilterError(where.str() + ": log-probability +inf at cell " + std::to_string(i));
      }
      value = std::isinf(raw) ? kLogZero : raw;  // -inf: probability 0
    }
    f.log_prob[bin * (cells / static_cast<std::size_t>(volume.bins)) + pixel] = value;
    if (value > max) {
      max = value;
      max_index = i;
    }
  }
  if (max <= kLogZero) throw FilterError(where.str() + ": no probability mass (every cell is zero)");
  // log-softmax over all cells, and the normalized entropy.
  double sum = 0;
  for (float v : f.log_prob) sum += std::exp(static_cast<double>(v) - max);
  const double lse = max + std::log(sum);
  double entropy = 0;
  for (float& v : f.log_prob) {
    if (v <= kLogZero) continue;
    const double l = static_cast<double>(v) - lse;
    v = static_cast<float>(l);
    entropy -= std::exp(l) * l;
  }
  f.entropy = std::clamp(entropy / f.log_cells, 0.0, 1.0);
  f.argmax_bin = static_cast<int>(max_index % static_cast<std::size_t>(volume.bins));
  const std::size_t pixel = max_index / static_cast<std::size_t>(volume.bins);
  f.argmax_v = static_cast<int>(pixel / static_cast<std::size_t>(volume.width));
  f.argmax_u = static_cast<int>(pixel % static_cast<std::size_t>(volume.width));
  return f;
}

Pose volume_cell_pose(const PreparedFrame& frame, const CropPose& crop, int v, int u, double bin) {
  // Inverse of the sampling map in SeqLocFilter::Impl::sample_frame.
  const double east = (u - (frame.width - 1) / 2.0) * frame.cell_m;
  const double north = -(v - (frame.height - 1) / 2.0) * frame.cell_m;
  const double a = crop.rotation_deg * kDegToRad;
  // Crop axes are the window's rotated by a clockwise.
  const double dx = east * std::cos(a) + north * std::sin(a);
  const double dy = -east * std::sin(a) + north * std::cos(a);
  return {crop.centre_u + dx / kCellM, crop.centre_v - dy / kCellM, wrap_degrees(bin * 360.0 / frame.bins + crop.rotation_deg)};
}

Pose peak_anchored_position(const BeliefVolume& belief, int u_star, int v_star, int radius) {
  // x_hat = sum m(x) x / sum m(x) over the cells around x*, m(x) = sum_th exp(b(x, th)).
  double sm = 0, su = 0, sv = 0;
  for (int v = std::max(0, v_star - radius); v <= std::min(belief.height() - 1, v_star + radius); ++v) {
    for (int u = std::max(0, u_star - radius); u <= std::min(belief.width() - 1, u_star + radius); ++u) {
      const double m = belief.position_mass(u, v);
      sm += m;
      su += m * u;
      sv += m * v;
    }
  }
  if (!(sm > 0)) return {static_cast<double>(u_star), static_cast<double>(v_star), 0};
  return {su / sm, sv / sm, 0};
}

Pose single_frame_pose(const PreparedFrame& frame, const CropPose& crop) {
  return volume_cell_pose(frame, crop, frame.argmax_v, frame.argmax_u, frame.argmax_bin);
}

std::vector<float> road_prior_log_q(const float* road_distance_m, int width, int height, int headings, double sigma_m) {
  const std::size_t n = static_cast<std::size_t>(width) * height;
  std::vector<double> g(n);
  double z = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const double d = road_distance_m[i];
    g[i] = std::exp(-d * d / (2 * sigma_m * sigma_m));
    z += g[i];
  }
  std::vector<float> log_q(n);
  for (std::size_t i = 0; i < n; ++i) {
    const double q = (0.9 * (z > 0 ? g[i] / z : 0.0) + 0.1 / static_cast<double>(n)) / headings;
    log_q[i] = static_cast<float>(std::log(q));
  }
  return log_q;
}

// ---------------------------------------------------------------------------------------------
// The filter

struct SeqLocFilter::Impl {
  BeliefVolume scratch;  // the other buffer of predict
  struct Worker {
    std::vector<float> sample, blend;
    Eigen::ArrayXf t0, t1;
  };
  std::vector<Worker> workers;

  Impl(const FilterConfig& c) : scratch(c.width, c.height, c.headings), workers(static_cast<std::size_t>(c.threads)) {
    const std::size_t n = static_cast<std::size_t>(c.width) * c.height;
    for (auto& w : workers) {
      w.sample.resize(n);
      w.t0.resize(static_cast<Eigen::Index>(n));
      w.t1.resize(static_cast<Eigen::Index>(n));
    }
  }

  void sample_frame(const PreparedFrame& f, const CropPose& crop, double heading_deg, int width, int height,
                    Worker& worker, float* out) const {
    detail::sample_frame_slice(f, crop, heading_deg, width, height, worker.blend, out);
  }
};

void detail::sample_frame_slice(const PreparedFrame& f, const CropPose& crop, double heading_deg, int width,
                                int height, std::vector<float>& blend_buffer, float* out) {
  {
    const auto no_info = static_cast<float>(-f.log_cells);
    // Heading: the crop's own heading of window heading h is h - rotation.
    const double p = wrap_degrees(heading_deg - crop.rotation_deg) * f.bins / 360.0;
    const int j0 = static_cast<int>(std::floor(p)) % f.bins;
    const int j1 = (j0 + 1) % f.bins;
    const auto a = static_cast<float>(p - std::floor(p));
    const std::size_t slice = static_cast<std::size_t>(f.width) * f.height;
    const float* s0 = f.log_prob.data() + static_cast<std::size_t>(j0) * slice;
    const float* s1 = f.log_prob.data() + static_cast<std::size_t>(j1) * slice;
    const float* blended = s0;
    if (a > 0) {
      blend_buffer.resize(slice);
      for (std::size_t i = 0; i < slice; ++i) blend_buffer[i] = (1 - a) * s0[i] + a * s1[i];
      blended = blend_buffer.data();
    }
    const double scale = kCellM / f.cell_m;
    if (crop.rotation_deg == 0.0 && scale == 1.0) {
      // Axis-aligned, same cells: a translation (crops served by seqloc itself).
      translate(blended, f.width, f.height, out, width, height, (f.width - 1) / 2.0 - crop.centre_u,
                (f.height - 1) / 2.0 - crop.centre_v, no_info);
      return;
    }
    // General affine map from window cells to volume cells.
    const double r = crop.rotation_deg * kDegToRad, c = std::cos(r), s = std::sin(r);
    const double cu = (f.width - 1) / 2.0, cv = (f.height - 1) / 2.0;
    for (int v = 0; v < height; ++v) {
      for (int u = 0; u < width; ++u) {
        const double du = u - crop.centre_u, dv = v - crop.centre_v;
        const double x = cu + scale * (du * c + dv * s);
        const double y = cv + scale * (-du * s + dv * c);
        float value = no_info;
        if (x >= 0 && y >= 0 && x <= f.width - 1 && y <= f.height - 1) {
          const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
          const int x1 = std::min(x0 + 1, f.width - 1), y1 = std::min(y0 + 1, f.height - 1);
          const auto ax = static_cast<float>(x - x0), ay = static_cast<float>(y - y0);
          const float* r0 = blended + static_cast<std::size_t>(y0) * f.width;
          const float* r1 = blended + static_cast<std::size_t>(y1) * f.width;
          value = (1 - ay) * ((1 - ax) * r0[x0] + ax * r0[x1]) + ay * ((1 - ax) * r1[x0] + ax * r1[x1]);
        }
        out[static_cast<std::size_t>(v) * width + u] = value;
      }
    }
  }
}

SeqLocFilter::SeqLocFilter(const FilterConfig& config)
    : config_((config.validate(), config)),
      belief_(config.width, config.height, config.headings),
      impl_(std::make_unique<Impl>(config)) {}

SeqLocFilter::~SeqLocFilter() = default;

void SeqLocFilter::reset_uniform() {
  belief_.set_uniform();
  first_ = true;
  last_estimate_.reset();
}

void SeqLocFilter::reset_gaussian(double u, double v, double sigma_m) {
  belief_.set_gaussian(u, v, sigma_m / kCellM);
  first_ = true;
  last_estimate_.reset();
}

void SeqLocFilter::recentre(int du, int dv) {
  belief_.recentre(du, dv);
  if (last_estimate_) {
    last_estimate_->u -= du;
    last_estimate_->v -= dv;
  }
}

void detail::warp_volume(const BeliefVolume& in, BeliefVolume& out, const Odometry& odometry, float fill,
                         int threads) {
  const int W = in.width(), H = in.height(), R = in.headings();
  // New bin k takes source bins k + s and k + s + 1 (heading k * 360 / R + yaw), weights 1 - a, a.
  const double p = odometry.yaw_deg * R / 360.0;
  const double floor_p = std::floor(p);
  const auto a = static_cast<float>(p - floor_p);
  const int s = static_cast<int>(((static_cast<long long>(floor_p) % R) + R) % R);
  const std::size_t n = in.slice_cells();
  const auto N = static_cast<Eigen::Index>(n);
  // Interpolation is in the probability domain, so that moving a peak keeps its mass: each
  // source slice is scaled by its maximum, exponentiated, translated bilinearly; the blend of two
  // slices is taken back to logs once per cell.
  struct Translated {
    std::vector<float> prob;
    float log_scale = 0;
  };
  auto translated = [&](int j, Translated& t, std::vector<float>& exp_buffer) {
    double du = 0, dv = 0;
    displacement_cells(odometry, in.bin_heading_deg(j), du, dv);
    ConstArrayMap src(in.slice(j), N);
    t.log_scale = std::max(src.maxCoeff(), fill);
    exp_buffer.resize(n);
    ArrayMap(exp_buffer.data(), N) = (src - t.log_scale).exp();
    t.prob.resize(n);
    translate(exp_buffer.data(), W, H, t.prob.data(), W, H, -du, -dv, std::exp(fill - t.log_scale));
  };
  // Exact value of one cell from the source logs (stable log-sum-exp of the weighted neighbours),
  // for the cells whose probabilities underflow float.
  auto exact = [&](int u, int v, int k) {
    double terms[8] = {}, weights[8] = {};
    int count = 0;
    const int j0 = (k + s) % R;
    for (int side = 0; side < 2; ++side) {
      const int j = (j0 + side) % R;
      const double wj = side == 0 ? 1.0 - a : a;
      if (wj == 0) continue;
      double du = 0, dv = 0;
      displacement_cells(odometry, in.bin_heading_deg(j), du, dv);
      const double x = u - du, y = v - dv;
      if (x < 0 || y < 0 || x > W - 1 || y > H - 1) {
        terms[count] = fill;
        weights[count++] = wj;
        continue;
      }
      const int x0 = static_cast<int>(std::floor(x)), y0 = static_cast<int>(std::floor(y));
      const int x1 = std::min(x0 + 1, W - 1), y1 = std::min(y0 + 1, H - 1);
      const double ax = x - x0, ay = y - y0;
      const int xs[4] = {x0, x1, x0, x1}, ys[4] = {y0, y0, y1, y1};
      const double ws[4] = {(1 - ax) * (1 - ay), ax * (1 - ay), (1 - ax) * ay, ax * ay};
      for (int i = 0; i < 4; ++i) {
        if (ws[i] == 0) continue;
        terms[count] = in.at(xs[i], ys[i], j);
        weights[count++] = wj * ws[i];
      }
    }
    double m = terms[0];
    for (int i = 1; i < count; ++i) m = std::max(m, terms[i]);
    double sum = 0;
    for (int i = 0; i < count; ++i) sum += weights[i] * std::exp(terms[i] - m);
    return sum > 0 ? static_cast<float>(m + std::log(sum)) : kLogZero;
  };
  detail::parallel_chunks(R, threads, [&](int k0, int k1, int) {
    Translated current, next;
    std::vector<float> exp_buffer;
    Eigen::ArrayXf mix(N);
    translated((k0 + s) % R, current, exp_buffer);
    for (int k = k0; k < k1; ++k) {
      ArrayMap dst(out.slice(k), N);
      ConstArrayMap p0(current.prob.data(), N);
      float scale = current.log_scale;
      if (a == 0.0f) {
        mix = p0;
      } else {
        translated((k + s + 1) % R, next, exp_buffer);
        ConstArrayMap p1(next.prob.data(), N);
        scale = std::max(current.log_scale, next.log_scale);
        mix = (1 - a) * std::exp(current.log_scale - scale) * p0 + a * std::exp(next.log_scale - scale) * p1;
      }
      dst = mix.log() + scale;
      // Cells more than ~69 nats below their slice's maximum: float's exp (which Eigen clamps at
      // the smallest normal instead of 0) cannot represent them, so they take the exact formula.
      constexpr float kSmallest = 1e-30f;
      for (Eigen::Index i = 0; i < N; ++i) {
        if (!(mix[i] > kSmallest)) dst[i] = exact(static_cast<int>(i % W), static_cast<int>(i / W), k);
      }
      if (a == 0.0f) {
        if (k + 1 < k1) translated((k + 1 + s) % R, current, exp_buffer);
      } else {
        std::swap(current, next);
      }
    }
  });
}

void SeqLocFilter::predict(const Odometry& odometry) {
  const int W = config_.width, H = config_.height, R = config_.headings;
  detail::warp_volume(belief_, impl_->scratch, odometry, belief_.min_value(), config_.threads);
  std::swap(belief_, impl_->scratch);

  if (config_.motion_noise) {
    const double step_m = std::hypot(odometry.forward_m, odometry.left_m);
    const double sigma_cells = config_.motion_noise_xy_per_m * step_m / kCellM;
    const double sigma_bins = config_.motion_noise_deg_per_m * step_m * R / 360.0;
    // Diffusion in the probability domain: separable Gaussian blur in u, v and (circular) heading.
    auto kernel = [](double sigma) {
      std::vector<double> k;
      if (sigma < 1e-3) return std::vector<double>{1.0};
      const int radius = static_cast<int>(std::ceil(3 * sigma));
      double sum = 0;
      for (int i = -radius; i <= radius; ++i) {
        k.push_back(std::exp(-0.5 * i * i / (sigma * sigma)));
        sum += k.back();
      }
      for (double& x : k) x /= sum;
      return k;
    };
    const auto kx = kernel(sigma_cells), kh = kernel(sigma_bins);
    const float max = *std::max_element(belief_.data(), belief_.data() + belief_.size());
    std::vector<double> prob(belief_.size()), tmp(belief_.size());
    for (std::size_t i = 0; i < prob.size(); ++i) prob[i] = std::exp(static_cast<double>(belief_.data()[i]) - max);
    const int rx = static_cast<int>(kx.size() / 2), rh = static_cast<int>(kh.size() / 2);
    const std::size_t n = belief_.slice_cells();
    auto idx = [&](int u, int v, int k) { return static_cast<std::size_t>(k) * n + static_cast<std::size_t>(v) * W + u; };
    for (int k = 0; k < R; ++k)  // u (mass beyond the window edge is lost, as in predict)
      for (int v = 0; v < H; ++v)
        for (int u = 0; u < W; ++u) {
          double acc = 0;
          for (int i = -rx; i <= rx; ++i) {
            if (u + i >= 0 && u + i < W) acc += kx[static_cast<std::size_t>(i + rx)] * prob[idx(u + i, v, k)];
          }
          tmp[idx(u, v, k)] = acc;
        }
    for (int k = 0; k < R; ++k)  // v
      for (int v = 0; v < H; ++v)
        for (int u = 0; u < W; ++u) {
          double acc = 0;
          for (int i = -rx; i <= rx; ++i) {
            if (v + i >= 0 && v + i < H) acc += kx[static_cast<std::size_t>(i + rx)] * tmp[idx(u, v + i, k)];
          }
          prob[idx(u, v, k)] = acc;
        }
    for (int k = 0; k < R; ++k)  // heading, circular
      for (std::size_t c = 0; c < n; ++c) {
        double acc = 0;
        for (int i = -rh; i <= rh; ++i) acc += kh[static_cast<std::size_t>(i + rh)] * prob[static_cast<std::size_t>((k + i + R) % R) * n + c];
        tmp[static_cast<std::size_t>(k) * n + c] = acc;
      }
    for (std::size_t i = 0; i < prob.size(); ++i) {
      belief_.data()[i] = tmp[i] > 0 ? static_cast<float>(std::log(tmp[i]) + max) : kLogZero;
    }
  }
}

FrameResult SeqLocFilter::step(const PreparedFrame& frame, const CropPose& crop, const Odometry& odometry,
                               const float* road_distance_m, const GpsFix* gps) {
  if (config_.mgr && road_distance_m == nullptr) throw FilterError("MGR is on but no road-distance window was given");
  const int W = config_.width, H = config_.height, R = config_.headings;
  const std::size_t n = belief_.slice_cells();
  if (!first_) predict(odometry);

  FrameResult result;
  result.frame_entropy = frame.entropy;
  result.etu_weight = config_.etu ? etu_weight(frame.entropy) : 1.0;
  const auto w = static_cast<float>(result.etu_weight);

  std::vector<float> gps_term;
  if (config_.gps_prior && gps != nullptr) {
    gps_term.resize(n);
    const double sigma_cells = gps->sigma_m / kCellM;
    for (int v = 0; v < H; ++v)
      for (int u = 0; u < W; ++u) {
        const double du = u - gps->u, dv = v - gps->v;
        gps_term[static_cast<std::size_t>(v) * W + u] =
            static_cast<float>(-(du * du + dv * dv) / (2 * sigma_cells * sigma_cells));
      }
  }

  // Update: b = w * log p + b_hat per slice, with each slice's max and sum of exp while it is hot.
  std::vector<double> slice_max(static_cast<std::size_t>(R)), slice_sum(static_cast<std::size_t>(R));
  detail::parallel_chunks(R, config_.threads, [&](int k0, int k1, int t) {
    auto& worker = impl_->workers[static_cast<std::size_t>(t)];
    for (int k = k0; k < k1; ++k) {
      impl_->sample_frame(frame, crop, belief_.bin_heading_deg(k), W, H, worker, worker.sample.data());
      ArrayMap b(belief_.slice(k), static_cast<Eigen::Index>(n));
      b += w * ConstArrayMap(worker.sample.data(), static_cast<Eigen::Index>(n));
      if (!gps_term.empty()) b += ConstArrayMap(gps_term.data(), static_cast<Eigen::Index>(n));
      const float m = b.maxCoeff();
      slice_max[static_cast<std::size_t>(k)] = m;
      worker.t0 = (b - m).exp();
      slice_sum[static_cast<std::size_t>(k)] = static_cast<double>(worker.t0.sum());
    }
  });
  const double global_max = *std::max_element(slice_max.begin(), slice_max.end());
  double total = 0;
  for (int k = 0; k < R; ++k) {
    total += slice_sum[static_cast<std::size_t>(k)] * std::exp(slice_max[static_cast<std::size_t>(k)] - global_max);
  }
  const auto lse = static_cast<float>(global_max + std::log(total));

  // Normalize, MGR, argmax.
  std::vector<float> log_eps_q;
  if (config_.mgr) {
    log_eps_q = road_prior_log_q(road_distance_m, W, H, R, config_.mgr_sigma_m);
    const auto log_eps = static_cast<float>(std::log(config_.mgr_epsilon));
    for (float& l : log_eps_q) l += log_eps;
  }
  const auto shift = static_cast<float>(lse - (config_.mgr ? std::log1p(-config_.mgr_epsilon) : 0.0));
  std::vector<float> best_value(static_cast<std::size_t>(R), -std::numeric_limits<float>::infinity());
  std::vector<Eigen::Index> best_index(static_cast<std::size_t>(R), 0);
  detail::parallel_chunks(R, config_.threads, [&](int k0, int k1, int t) {
    auto& worker = impl_->workers[static_cast<std::size_t>(t)];
    for (int k = k0; k < k1; ++k) {
      ArrayMap b(belief_.slice(k), static_cast<Eigen::Index>(n));
      if (config_.mgr) {
        // log((1 - eps) e^b' + eps q) = max + log1p(exp(-|x - y|)) with x = b' + log(1 - eps), y = log(eps q).
        ConstArrayMap y(log_eps_q.data(), static_cast<Eigen::Index>(n));
        worker.t0 = b - shift;
        worker.t1 = worker.t0.max(y);
        b = worker.t1 + (-(worker.t0 - y).abs()).exp().log1p();
      } else {
        b -= shift;
      }
      Eigen::Index index = 0;
      best_value[static_cast<std::size_t>(k)] = b.maxCoeff(&index);
      best_index[static_cast<std::size_t>(k)] = index;
    }
  });
  int k_star = 0;
  for (int k = 1; k < R; ++k) {
    if (best_value[static_cast<std::size_t>(k)] > best_value[static_cast<std::size_t>(k_star)]) k_star = k;
  }
  const auto cell = static_cast<int>(best_index[static_cast<std::size_t>(k_star)]);
  const int u_star = cell % W, v_star = cell / W;
  result.peak_log_belief = best_value[static_cast<std::size_t>(k_star)];
  result.argmax = {static_cast<double>(u_star), static_cast<double>(v_star), belief_.bin_heading_deg(k_star)};
  result.pose = result.argmax;

  if (config_.pas) {
    const Pose x_hat = peak_anchored_position(belief_, u_star, v_star, config_.pas_radius);
    result.pose.u = x_hat.u;
    result.pose.v = x_hat.v;
  }
  if (config_.subbin_heading) {
    // Circular mean of the bin headings around th* at x*, weighted by the belief.
    double sx = 0, sy = 0;
    for (int i = -config_.subbin_half_width; i <= config_.subbin_half_width; ++i) {
      const int k = (k_star + i + R) % R;
      const double weight = std::exp(static_cast<double>(belief_.at(u_star, v_star, k) - result.peak_log_belief));
      const double h = belief_.bin_heading_deg(k) * kDegToRad;
      sx += weight * std::sin(h);
      sy += weight * std::cos(h);
    }
    result.pose.heading_deg = wrap_degrees(std::atan2(sx, sy) / kDegToRad);
  }
  if (last_estimate_ && !first_) {
    double du = 0, dv = 0;
    displacement_cells(odometry, last_estimate_->heading_deg, du, dv);
    const double pu = last_estimate_->u + du, pv = last_estimate_->v + dv;
    result.relocalized = std::hypot(result.argmax.u - pu, result.argmax.v - pv) * kCellM > config_.relocalization_jump_m;
  }
  last_estimate_ = result.pose;
  first_ = false;
  return result;
}

}  // namespace seqloc::filter
