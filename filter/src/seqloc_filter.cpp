#include "seqloc/filter/seqloc_filter.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>

#include <Eigen/Core>

#include "internal.hpp"
#include "seqloc/core/angles.hpp"
#include "seqloc/core/thread_pool.hpp"
#include "seqloc/core/units.hpp"

namespace seqloc::filter {
namespace {

using core::kCellM;
using core::kDegToRad;

using ArrayMap = Eigen::Map<Eigen::ArrayXf>;
using ConstArrayMap = Eigen::Map<const Eigen::ArrayXf>;

/// Log-softmax of f.log_prob in place (max: its largest value), with the normalized entropy and
/// the argmax; `chunks` workers. With `shift` false the values stay as they are and only the
/// summary (entropy under their own normalizer, peak, argmax) is computed.
void normalize(PreparedFrame& f, float max, int chunks, bool shift = true) {
  const std::size_t slice = static_cast<std::size_t>(f.height) * static_cast<std::size_t>(f.width);
  const std::size_t cells = f.log_prob.size();
  const int W = f.width;
  // log-softmax over all cells and the normalized entropy, in blocks (float within a block,
  // double across): with e = exp(x - max), S = sum e, lse = max + log S,
  // H = -sum (e / S)(x - lse) = lse - sum(e x) / S.
  constexpr Eigen::Index kBlock = 4096;
  std::vector<double> chunk_sum(static_cast<std::size_t>(chunks)), chunk_ex(static_cast<std::size_t>(chunks));
  const auto blocks = static_cast<int>((static_cast<Eigen::Index>(cells) + kBlock - 1) / kBlock);
  core::parallel_chunks(blocks, chunks, [&](int b0, int b1, int t) {
    Eigen::ArrayXf e(kBlock);
    double s_sum = 0, s_ex = 0;
    for (int block = b0; block < b1; ++block) {
      const Eigen::Index start = block * kBlock;
      const Eigen::Index len = std::min<Eigen::Index>(kBlock, static_cast<Eigen::Index>(cells) - start);
      ConstArrayMap x(f.log_prob.data() + start, len);
      auto eb = e.head(len);
      detail::exp_or_zero(x.data(), static_cast<std::size_t>(len), 1.0f, max, eb.data());
      s_sum += eb.sum();
      s_ex += (eb * x.max(kLogZero)).sum();  // 0 * kLogZero at a zero cell, which may hold -inf (rounded)
    }
    chunk_sum[static_cast<std::size_t>(t)] = s_sum;
    chunk_ex[static_cast<std::size_t>(t)] = s_ex;
  });
  double sum = 0, ex = 0;
  for (int t = 0; t < chunks; ++t) {
    sum += chunk_sum[static_cast<std::size_t>(t)];
    ex += chunk_ex[static_cast<std::size_t>(t)];
  }
  const double lse = max + std::log(sum);
  f.entropy = std::clamp((lse - ex / sum) / f.log_cells, 0.0, 1.0);
  if (!shift) {
    f.max_log_prob = max;
    const std::size_t best = static_cast<std::size_t>(std::find(f.log_prob.begin(), f.log_prob.end(), max) - f.log_prob.begin());
    f.argmax_bin = static_cast<int>(best / slice);
    f.argmax_v = static_cast<int>(best % slice / static_cast<std::size_t>(W));
    f.argmax_u = static_cast<int>(best % static_cast<std::size_t>(W));
    return;
  }
  core::parallel_chunks(blocks, chunks, [&](int b0, int b1, int) {
    const Eigen::Index start = b0 * kBlock;
    const Eigen::Index stop = std::min<Eigen::Index>(static_cast<Eigen::Index>(b1) * kBlock, static_cast<Eigen::Index>(cells));
    ArrayMap x(f.log_prob.data() + start, stop - start);
    x = (x > kLogZero).select(x - static_cast<float>(lse), kLogZero);
  });
  // The argmax, first in heading-major order: its value is max - lse exactly.
  const float top = max - static_cast<float>(lse);  // computed as in the pass above
  f.max_log_prob = top;
  const std::size_t best = static_cast<std::size_t>(std::find(f.log_prob.begin(), f.log_prob.end(), top) - f.log_prob.begin());
  f.argmax_bin = static_cast<int>(static_cast<std::size_t>(best) / slice);
  f.argmax_v = static_cast<int>(static_cast<std::size_t>(best) % slice / static_cast<std::size_t>(W));
  f.argmax_u = static_cast<int>(static_cast<std::size_t>(best) % static_cast<std::size_t>(W));
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

PreparedFrame prepare_frame(const FrameVolume& volume, int window_headings, int threads) {
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
  const int H = volume.height, W = volume.width, N = volume.bins;
  const std::size_t slice = static_cast<std::size_t>(H) * W;
  const std::size_t cells = slice * static_cast<std::size_t>(N);
  f.log_cells = std::log(static_cast<double>(cells));
  f.log_prob.resize(cells);
  // Per chunk of bins, in parallel: transpose (H, W, N) to heading-major one source row at a
  // time (it stays in cache), convert, check, map -inf to kLogZero and find the chunk's maximum.
  constexpr float kInf = std::numeric_limits<float>::infinity();
  const bool is_prob = volume.values == VolumeValues::prob;
  const int chunks = std::max(1, std::min(threads, N));
  std::vector<float> chunk_max(static_cast<std::size_t>(chunks), -kInf);
  std::vector<char> chunk_bad(static_cast<std::size_t>(chunks), 0);
  core::parallel_chunks(N, chunks, [&](int j0, int j1, int t) {
    for (int v = 0; v < H; ++v) {
      const std::size_t row = static_cast<std::size_t>(v) * W * N;
      for (int j = j0; j < j1; ++j) {
        float* dst = f.log_prob.data() + static_cast<std::size_t>(j) * slice + static_cast<std::size_t>(v) * W;
        if (volume.type == VolumeType::float32) {
          const float* src = static_cast<const float*>(volume.data) + row + j;
          for (int u = 0; u < W; ++u) dst[u] = src[static_cast<std::size_t>(u) * N];
        } else {
          const std::uint16_t* src = static_cast<const std::uint16_t*>(volume.data) + row + j;
          for (int u = 0; u < W; ++u) dst[u] = half_to_float(src[static_cast<std::size_t>(u) * N]);
        }
      }
    }
    const std::size_t begin = static_cast<std::size_t>(j0) * slice, end = static_cast<std::size_t>(j1) * slice;
    ArrayMap x(f.log_prob.data() + begin, static_cast<Eigen::Index>(end - begin));
    bool bad = false;
    if (is_prob) {
      bad = !(x >= 0).all() || (x == kInf).any();  // NaN fails x >= 0
      if (!bad) x = (x > 0).select(x.log(), kLogZero);
    } else {
      bad = x.isNaN().any() || (x == kInf).any();
      if (!bad) x = (x == -kInf).select(kLogZero, x);
    }
    chunk_bad[static_cast<std::size_t>(t)] = static_cast<char>(bad);
    if (!bad) chunk_max[static_cast<std::size_t>(t)] = x.maxCoeff();
  });
  const bool bad = std::find(chunk_bad.begin(), chunk_bad.end(), 1) != chunk_bad.end();
  const float max = *std::max_element(chunk_max.begin(), chunk_max.end());
  if (bad) {
    // Name the first offending cell by its index in the file's (H, W, N) order.
    for (int v = 0; v < H; ++v)
      for (int u = 0; u < W; ++u)
        for (int j = 0; j < N; ++j) {
          const std::size_t i = (static_cast<std::size_t>(v) * W + u) * N + j;
          const float raw = volume.type == VolumeType::float32
                                ? static_cast<const float*>(volume.data)[i]
                                : half_to_float(static_cast<const std::uint16_t*>(volume.data)[i]);
          std::string what;
          if (std::isnan(raw)) what = "NaN";
          if (raw == kInf) what = is_prob ? "probability +inf" : "log-probability +inf";
          if (is_prob && raw < 0) what = "probability " + std::to_string(raw) + " < 0";
          if (!what.empty()) throw FilterError(where.str() + ": " + what + " at cell " + std::to_string(i));
        }
  }
  if (max <= kLogZero) throw FilterError(where.str() + ": no probability mass (every cell is zero)");
  normalize(f, max, chunks);
  return f;
}

void temper_frame_in_place(PreparedFrame& frame, double power, int threads) {
  if (!(power > 0) || !std::isfinite(power)) {
    throw FilterError("temper_frame: the power must be finite and > 0, not " + std::to_string(power),
                      ErrorCategory::usage);
  }
  if (power == 1.0) return;
  ArrayMap x(frame.log_prob.data(), static_cast<Eigen::Index>(frame.log_prob.size()));
  // Zero cells stay zero; the peak's value is log p* scaled, and the log-softmax shifts it back.
  x = (x > kLogZero).select(x * static_cast<float>(power), kLogZero);
  const float max = x.maxCoeff();
  normalize(frame, max, std::max(1, std::min(threads, frame.bins)));
}

void summarize_frame(PreparedFrame& frame, int threads) {
  if (frame.log_prob.empty()) throw FilterError("summarize_frame: the frame has no cells");
  ConstArrayMap x(frame.log_prob.data(), static_cast<Eigen::Index>(frame.log_prob.size()));
  normalize(frame, x.maxCoeff(), std::max(1, std::min(threads, frame.bins)), /*shift=*/false);
}

PreparedFrame temper_frame(PreparedFrame frame, double power, int threads) {
  temper_frame_in_place(frame, power, threads);
  return frame;
}

double route_reference_entropy(std::span<const double> entropies) {
  const std::size_t n = std::min(entropies.size(), kEtuRouteFrames);
  std::vector<double> last(entropies.end() - static_cast<std::ptrdiff_t>(n), entropies.end());
  std::nth_element(last.begin(), last.begin() + static_cast<std::ptrdiff_t>(n / 2), last.end());
  return last[n / 2];
}

Pose volume_cell_pose(const PreparedFrame& frame, const CropPose& crop, int v, int u, double bin) {
  // Inverse of the sampling map in SeqLocFilter::Impl::sample_frame.
  const double east = (u - (frame.width - 1) / 2.0) * frame.cell_m;
  const double north = -(v - (frame.height - 1) / 2.0) * frame.cell_m;
  const double a = crop.rotation_deg * kDegToRad;
  // Crop axes are the window's rotated by a clockwise.
  const double dx = east * std::cos(a) + north * std::sin(a);
  const double dy = -east * std::sin(a) + north * std::cos(a);
  return {crop.centre_u + dx / kCellM, crop.centre_v - dy / kCellM,
          core::wrap360(bin * 360.0 / frame.bins + crop.rotation_deg)};
}

Pose single_frame_pose(const PreparedFrame& frame, const CropPose& crop) {
  return volume_cell_pose(frame, crop, frame.argmax_v, frame.argmax_u, frame.argmax_bin);
}

std::vector<float> road_prior_g(std::span<const float> distance_m, double sigma_m) {
  std::vector<float> g(distance_m.size());
  float last = 0, value = 1.0f;
  for (std::size_t i = 0; i < distance_m.size(); ++i) {
    if (i == 0 || distance_m[i] != last) {
      last = distance_m[i];
      value = static_cast<float>(road_prior_g(static_cast<double>(last), sigma_m));
    }
    g[i] = value;
  }
  return g;
}

std::vector<float> road_prior_log_q(const float* road_distance_m, int width, int height, int headings, double sigma_m) {
  const std::size_t n = static_cast<std::size_t>(width) * height;
  std::vector<double> g(n);
  double z = 0;
  for (std::size_t i = 0; i < n; ++i) {
    g[i] = road_prior_g(road_distance_m[i], sigma_m);
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

void detail::translate(const float* src, int sw, int sh, float* dst, int dw, int dh, double ou, double ov, float fill) {
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

void detail::sample_slice(const float* values, int bins, int vh, int vw, double cell_m, const CropPose& crop,
                          double heading_deg, int width, int height, float fill, std::vector<float>& blend_buffer,
                          float* out) {
  // Heading: the crop's own heading of window heading h is h - rotation.
  const double p = core::wrap360(heading_deg - crop.rotation_deg) * bins / 360.0;
  const int j0 = static_cast<int>(std::floor(p)) % bins;
  const int j1 = (j0 + 1) % bins;
  const auto a = static_cast<float>(p - std::floor(p));
  const std::size_t slice = static_cast<std::size_t>(vw) * vh;
  const float* s0 = values + static_cast<std::size_t>(j0) * slice;
  const float* s1 = values + static_cast<std::size_t>(j1) * slice;
  const float* blended = s0;
  if (a > 0) {
    blend_buffer.resize(slice);
    for (std::size_t i = 0; i < slice; ++i) blend_buffer[i] = (1 - a) * s0[i] + a * s1[i];
    blended = blend_buffer.data();
  }
  const double scale = kCellM / cell_m;
  if (crop.rotation_deg == 0.0 && scale == 1.0) {
    // Axis-aligned, same cells: a translation (crops served by seqloc itself).
    translate(blended, vw, vh, out, width, height, (vw - 1) / 2.0 - crop.centre_u, (vh - 1) / 2.0 - crop.centre_v,
              fill);
    return;
  }
  // General affine map from window cells to volume cells: the crop's axes are the window's
  // turned clockwise by the rotation.
  const double r = crop.rotation_deg * kDegToRad, c = std::cos(r), s = std::sin(r);
  const double cu = (vw - 1) / 2.0, cv = (vh - 1) / 2.0;
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      const double du = u - crop.centre_u, dv = v - crop.centre_v;
      const double x = cu + scale * (du * c + dv * s);
      const double y = cv + scale * (-du * s + dv * c);
      float value = fill;
      if (x >= 0 && y >= 0 && x <= vw - 1 && y <= vh - 1) {
        const int x0 = static_cast<int>(x), y0 = static_cast<int>(y);
        const int x1 = std::min(x0 + 1, vw - 1), y1 = std::min(y0 + 1, vh - 1);
        const auto ax = static_cast<float>(x - x0), ay = static_cast<float>(y - y0);
        const float* r0 = blended + static_cast<std::size_t>(y0) * vw;
        const float* r1 = blended + static_cast<std::size_t>(y1) * vw;
        value = (1 - ay) * ((1 - ax) * r0[x0] + ax * r0[x1]) + ay * ((1 - ax) * r1[x0] + ax * r1[x1]);
      }
      out[static_cast<std::size_t>(v) * width + u] = value;
    }
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
  auto translated = [&](int j, float* dst) {
    double du = 0, dv = 0;
    displacement_cells(odometry, in.bin_heading_deg(j), du, dv);
    translate(in.slice(j), W, H, dst, W, H, -du, -dv, fill);
  };
  core::parallel_chunks(R, threads, [&](int k0, int k1, int) {
    std::vector<float> buffer_a(n), buffer_b(n);
    float* current = buffer_a.data();
    float* next = buffer_b.data();
    translated((k0 + s) % R, current);
    for (int k = k0; k < k1; ++k) {
      float* dst = out.slice(k);
      if (a == 0.0f) {
        std::copy(current, current + n, dst);
        if (k + 1 < k1) translated((k + 1 + s) % R, current);
        continue;
      }
      translated((k + s + 1) % R, next);
      for (std::size_t i = 0; i < n; ++i) dst[i] = (1 - a) * current[i] + a * next[i];
      std::swap(current, next);
    }
  });
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

// ---------------------------------------------------------------------------------------------
// The filter

namespace {

/// What the filter reads of a frame raised to a power: its peak log-probability and entropy.
struct FrameShape {
  float max_log_prob;
  double entropy;
};

}  // namespace

struct SeqLocFilter::Impl {
  BeliefVolume scratch;          // the other buffer of predict
  AlignedVector<float> tempered;  // the frame's q^w / max, heading-major
  PowerEstimator estimator;
  struct Worker {
    std::vector<float> sample, blend;
    AlignedVector<float> depth, mass;  // aligned: Eigen's SIMD log covers the same cells wherever they lie
    DepthHistogram frame_cells{DepthHistogram::kCount}, belief_in_crop;  // self-calibration's evidence, this worker's share
    double belief_outside = 0, outside_cells = 0;
  };
  std::vector<Worker> workers;

  explicit Impl(const FilterConfig& c)
      : scratch(c.width, c.height, c.headings),
        estimator(c.self_calibration_prior_octaves, c.self_calibration_outlier_share),
        workers(static_cast<std::size_t>(c.threads)) {
    for (auto& w : workers) {
      w.sample.resize(static_cast<std::size_t>(c.width) * c.height);
      if (c.self_calibrate) {
        w.depth.resize(w.sample.size());
        w.mass.resize(w.sample.size());
      }
    }
  }

  // One pass over the given frame for self-calibration: its cells binned by depth below the peak
  // (each worker's share in its frame_cells) and, for power k != 1, the peak and entropy of
  // q = p^k / Z: with r = log p - log p_max, log q_max = -log Z, Z = sum e^{k r} and
  // H = log Z - k sum(e^{k r} r) / Z. The sums are kept per heading bin and added in bin order,
  // so that they do not depend on the number of threads.
  FrameShape scan_frame(const PreparedFrame& f, double power, int threads) {
    const std::size_t slice = static_cast<std::size_t>(f.width) * f.height;
    std::vector<double> bin_z(static_cast<std::size_t>(f.bins)), bin_zr(static_cast<std::size_t>(f.bins));
    const bool raised = power != 1.0;
    const auto k = static_cast<float>(power);
    core::parallel_chunks(f.bins, threads, [&](int j0, int j1, int t) {
      constexpr std::size_t kBlock = 4096;
      Eigen::ArrayXf r(kBlock), one(kBlock), e(kBlock);  // aligned: sums that do not depend on the heap
      auto& cells = workers[static_cast<std::size_t>(t)].frame_cells;
      for (int j = j0; j < j1; ++j) {
        double z = 0, zr = 0;
        for (std::size_t start = 0; start < slice; start += kBlock) {
          const std::size_t len = std::min(kBlock, slice - start);
          const float* x = f.log_prob.data() + static_cast<std::size_t>(j) * slice + start;
          for (Eigen::Index i = 0; i < static_cast<Eigen::Index>(len); ++i) {  // vectorizes
            r[i] = std::max(x[i], kLogZero) - f.max_log_prob;
            one[i] = x[i] > kLogZero ? 1.0f : 0.0f;
          }
          cells.add_each({r.data(), len}, {one.data(), len});
          if (raised) {
            detail::exp_or_zero(x, len, k, f.max_log_prob, e.data());
            ConstArrayMap eb(e.data(), static_cast<Eigen::Index>(len));
            z += eb.sum();
            zr += (eb * ConstArrayMap(r.data(), static_cast<Eigen::Index>(len))).sum();  // 0 * kLogZero at a zero cell
          }
        }
        bin_z[static_cast<std::size_t>(j)] = z;
        bin_zr[static_cast<std::size_t>(j)] = zr;
      }
    });
    if (!raised) return {f.max_log_prob, f.entropy};
    double z = 0, zr = 0;
    for (int j = 0; j < f.bins; ++j) {
      z += bin_z[static_cast<std::size_t>(j)];
      zr += bin_zr[static_cast<std::size_t>(j)];
    }
    const double log_z = std::log(z);  // z >= 1: the peak's own cell counts e^0
    return {static_cast<float>(-log_z), std::clamp((log_z - power * zr / z) / f.log_cells, 0.0, 1.0)};
  }
};

namespace {

// Self-calibration's evidence from one window slice, before the update multiplies it in: the
// predicted belief's mass binned by the frame's depth r = log(s) / exponent at each cell of the
// crop (`sample` holds s = exp(exponent * r), or a negative value outside the crop, which is then
// replaced by `outside`). A cell whose s underflowed to 0 is counted at the deepest depth float
// can show, so that smaller powers are not credited with less mass than they would see.
void collect_evidence(const float* belief, float* sample, std::size_t n, double exponent, float outside,
                      AlignedVector<float>& depth, AlignedVector<float>& mass, DepthHistogram& in_crop,
                      double& belief_outside, double& outside_cells) {
  const auto count = static_cast<Eigen::Index>(n);
  const auto inverse = static_cast<float>(1.0 / exponent);
  const auto underflow = static_cast<float>(std::log(std::numeric_limits<float>::denorm_min()) / exponent);
  // The log in SIMD over the whole slice (NaN outside the crop), then in a loop that vectorizes
  // (restrict: the arrays do not overlap) the underflowed cells' depth, each cell's mass in the
  // crop (0 outside) and the outside fill.
  Eigen::Map<Eigen::ArrayXf>(depth.data(), count) = Eigen::Map<const Eigen::ArrayXf>(sample, count).log() * inverse;
  float* __restrict d = depth.data();
  float* __restrict m = mass.data();
  float* __restrict s = sample;
  const float* __restrict b = belief;
  std::size_t outside_count = 0;
  for (std::size_t i = 0; i < n; ++i) {
    const bool in = s[i] >= 0;
    outside_count += in ? 0 : 1;
    d[i] = s[i] > 0 ? d[i] : underflow;
    m[i] = in ? b[i] : 0.0f;
    s[i] = in ? s[i] : outside;
  }
  // b - m is b outside the crop and exactly 0 inside.
  const double outside_mass = (Eigen::Map<const Eigen::ArrayXf>(belief, count) - Eigen::Map<const Eigen::ArrayXf>(m, count)).sum();
  in_crop.add_each({depth.data(), n}, {mass.data(), n});
  belief_outside += outside_mass;
  outside_cells += static_cast<double>(outside_count);
}

}  // namespace

SeqLocFilter::SeqLocFilter(const FilterConfig& config)
    : config_((config.validate(), config)),
      belief_(config.width, config.height, config.headings),
      impl_(std::make_unique<Impl>(config)) {}

SeqLocFilter::~SeqLocFilter() = default;

void SeqLocFilter::reset_uniform() {
  belief_.set_uniform();
  cached_min_.reset();
  first_ = true;
  last_estimate_.reset();
  impl_->estimator.reset();
  entropies_.clear();
}

void SeqLocFilter::reset_gaussian(double u, double v, double sigma_m) {
  belief_.set_gaussian(u, v, sigma_m / kCellM);
  cached_min_.reset();
  first_ = true;
  last_estimate_.reset();
  impl_->estimator.reset();
  entropies_.clear();
}

const PowerEstimator& SeqLocFilter::calibration() const { return impl_->estimator; }

void SeqLocFilter::rebase(BeliefVolume belief, const std::optional<Pose>& last_estimate) {
  if (belief.width() != belief_.width() || belief.height() != belief_.height() ||
      belief.headings() != belief_.headings()) {
    throw FilterError("rebase: the new belief is " + std::to_string(belief.width()) + " x " +
                      std::to_string(belief.height()) + " x " + std::to_string(belief.headings()) +
                      ", the filter's window " + std::to_string(belief_.width()) + " x " +
                      std::to_string(belief_.height()) + " x " + std::to_string(belief_.headings()));
  }
  belief_ = std::move(belief);
  cached_min_.reset();
  last_estimate_ = last_estimate;
}

void SeqLocFilter::recentre(int du, int dv) {
  belief_.recentre(du, dv);
  cached_min_.reset();
  if (last_estimate_) {
    last_estimate_->u -= du;
    last_estimate_->v -= dv;
  }
}

void SeqLocFilter::predict(const Odometry& odometry) {
  const int W = config_.width, H = config_.height, R = config_.headings;
  // The window's minimum: kept from the end of the last step unless the belief was handed out
  // for writing since.
  const float fill = cached_min_ ? *cached_min_ : belief_.min_value();
  detail::warp_volume(belief_, impl_->scratch, odometry, fill, config_.threads);
  cached_min_.reset();
  std::swap(belief_, impl_->scratch);

  if (config_.motion_noise) {
    const double step_m = std::hypot(odometry.forward_m, odometry.left_m);
    const double sigma_cells = config_.motion_noise_xy_per_m * step_m / kCellM;
    const double sigma_bins = config_.motion_noise_deg_per_m * step_m * R / 360.0;
    // Diffusion: separable Gaussian blur in u, v and (circular) heading; mass beyond the window
    // edge is lost, as in the motion itself.
    auto kernel = [](double sigma) {
      if (sigma < 1e-3) return std::vector<double>{1.0};
      std::vector<double> k;
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
    const int rx = static_cast<int>(kx.size() / 2), rh = static_cast<int>(kh.size() / 2);
    const std::size_t n = belief_.slice_cells();
    std::vector<float> tmp(belief_.size());
    float* p = belief_.data();
    auto idx = [&](int u, int v, int k) { return static_cast<std::size_t>(k) * n + static_cast<std::size_t>(v) * W + u; };
    for (int k = 0; k < R; ++k)
      for (int v = 0; v < H; ++v)
        for (int u = 0; u < W; ++u) {
          double acc = 0;
          for (std::size_t j = 0; j < kx.size(); ++j) {  // offsets -rx..rx
            const int uu = u + static_cast<int>(j) - rx;
            if (uu >= 0 && uu < W) acc += kx[j] * p[idx(uu, v, k)];
          }
          tmp[idx(u, v, k)] = static_cast<float>(acc);
        }
    for (int k = 0; k < R; ++k)
      for (int v = 0; v < H; ++v)
        for (int u = 0; u < W; ++u) {
          double acc = 0;
          for (std::size_t j = 0; j < kx.size(); ++j) {
            const int vv = v + static_cast<int>(j) - rx;
            if (vv >= 0 && vv < H) acc += kx[j] * tmp[idx(u, vv, k)];
          }
          p[idx(u, v, k)] = static_cast<float>(acc);
        }
    for (int k = 0; k < R; ++k)
      for (std::size_t c = 0; c < n; ++c) {
        double acc = 0;
        for (std::size_t j = 0; j < kh.size(); ++j) {  // offsets -rh..rh, wrapping in heading
          const int kk = (k + static_cast<int>(j) - rh + R) % R;
          acc += kh[j] * p[static_cast<std::size_t>(kk) * n + c];
        }
        tmp[static_cast<std::size_t>(k) * n + c] = static_cast<float>(acc);
      }
    std::copy(tmp.begin(), tmp.end(), p);
  }
}

FrameResult SeqLocFilter::step(const PreparedFrame& frame, const CropPose& crop, const Odometry& odometry,
                               const float* road_distance_m, const GpsFix* gps) {
  if (!first_) predict(odometry);
  FrameResult result = update(frame, crop, road_distance_m, gps);
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

FrameResult SeqLocFilter::update(const PreparedFrame& given, const CropPose& crop, const float* road_distance_m,
                                 const GpsFix* gps, const FrameWeighting* weighting) {
  if (config_.mgr && road_distance_m == nullptr)
    throw FilterError("MGR is on but no road-distance window was given", ErrorCategory::usage);
  // Self-calibration estimates from this frame unless a weighting repeats an earlier pass.
  const bool calibrating = config_.self_calibrate && weighting == nullptr;
  FrameResult result = weigh(given, weighting, calibrating);
  const float outside = temper(given, result);
  const double total = multiply_in(given, crop, outside, gps, result, calibrating);
  const Peak peak = normalize(total, road_distance_m);
  result.peak_log_belief = std::log(peak.value);
  result.argmax = {static_cast<double>(peak.u), static_cast<double>(peak.v), belief_.bin_heading_deg(peak.k)};
  result.pose = refine(peak);
  return result;
}

FrameResult SeqLocFilter::weigh(const PreparedFrame& given, const FrameWeighting* weighting, bool calibrating) {
  // Self-calibration: the frame raised to the power kappa the frames before it favour,
  // q = p^kappa / Z(kappa). q is never written out: its peak and entropy come from one pass over
  // the given frame, which also bins the frame's cells by depth for the estimator.
  FrameResult result;
  if (weighting != nullptr) {
    result.volume_power = weighting->volume_power;
    result.etu_weight = weighting->etu_weight;
  } else {
    result.volume_power = calibrating ? impl_->estimator.power() : 1.0;
  }
  if (calibrating) {
    for (auto& worker : impl_->workers) {
      worker.frame_cells.clear();
      worker.belief_in_crop.clear();
      worker.belief_outside = worker.outside_cells = 0;
    }
  }
  const FrameShape used = calibrating ? impl_->scan_frame(given, result.volume_power, config_.threads)
                          : weighting != nullptr ? FrameShape{weighting->peak_log_prob, given.entropy}
                                                 : FrameShape{given.max_log_prob, given.entropy};
  result.frame_entropy = used.entropy;
  if (weighting != nullptr) {
    // As weighed before.
  } else if (config_.etu && config_.etu_route_reference) {
    entropies_.push_back(given.entropy);
    if (entropies_.size() > 2 * kEtuRouteFrames) entropies_.erase(entropies_.begin(), entropies_.end() - kEtuRouteFrames);
    result.etu_weight = etu_weight(given.entropy, route_reference_entropy(entropies_));
  } else {
    result.etu_weight = config_.etu ? etu_weight(used.entropy, config_.etu_reference_entropy) : 1.0;
  }
  result.weighting = {result.volume_power, result.etu_weight, used.max_log_prob};
  return result;
}

float SeqLocFilter::temper(const PreparedFrame& frame, const FrameResult& result) {
  // The tempered likelihood q^w on the crop, scaled by its maximum (the scale cancels in the
  // normalization): exp(w kappa (log p - log p_max)); log(1/M) - outside_crop_nats outside the crop.
  const auto w = static_cast<float>(result.etu_weight);
  const float log_p_max = result.weighting.peak_log_prob;
  impl_->tempered.resize(frame.log_prob.size());
  const auto exponent_f = static_cast<float>(w * result.volume_power);
  core::parallel_chunks(frame.bins, config_.threads, [&](int j0, int j1, int) {
    const std::size_t slice = static_cast<std::size_t>(frame.width) * frame.height;
    for (int j = j0; j < j1; ++j) {  // bin by bin: the same cuts for any number of threads
      const std::size_t begin = static_cast<std::size_t>(j) * slice;
      detail::exp_or_zero(frame.log_prob.data() + begin, slice, exponent_f, frame.max_log_prob,
                          impl_->tempered.data() + begin);
    }
  });
  // The value of a window cell outside the crop.
  return static_cast<float>(std::exp(w * (-frame.log_cells - config_.outside_crop_nats - log_p_max)));
}

std::vector<float> SeqLocFilter::gps_factor(const GpsFix* gps) const {
  std::vector<float> factor;
  if (!config_.gps_prior || gps == nullptr) return factor;
  const int W = config_.width, H = config_.height;
  factor.resize(belief_.slice_cells());
  const double sigma_cells = gps->sigma_m / kCellM;
  for (int v = 0; v < H; ++v)
    for (int u = 0; u < W; ++u) {
      const double du = u - gps->u, dv = v - gps->v;
      factor[static_cast<std::size_t>(v) * W + u] =
          static_cast<float>(std::exp(-(du * du + dv * dv) / (2 * sigma_cells * sigma_cells)));
    }
  return factor;
}

double SeqLocFilter::multiply_in(const PreparedFrame& frame, const CropPose& crop, float outside, const GpsFix* gps,
                                 const FrameResult& result, bool calibrating) {
  const int W = config_.width, H = config_.height, R = config_.headings;
  const std::size_t n = belief_.slice_cells();
  const auto N = static_cast<Eigen::Index>(n);
  const std::vector<float> gps_factor = this->gps_factor(gps);
  // Update: b_hat + w log p, i.e. prob *= p^w, slice by slice with each slice's sum. The first
  // pass also collects self-calibration's evidence from the predicted belief.
  std::vector<double> slice_sum(static_cast<std::size_t>(R));
  const auto w = static_cast<float>(result.etu_weight);
  const double exponent = static_cast<double>(w) * result.volume_power;  // s = exp(exponent * r)
  auto update_slices = [&](bool with_prior) {
    const bool collect = calibrating && with_prior;
    core::parallel_chunks(R, config_.threads, [&](int k0, int k1, int t) {
      auto& worker = impl_->workers[static_cast<std::size_t>(t)];
      for (int k = k0; k < k1; ++k) {
        detail::sample_slice(impl_->tempered.data(), frame.bins, frame.height, frame.width, frame.cell_m, crop,
                             belief_.bin_heading_deg(k), W, H, collect ? -1.0f : outside, worker.blend,
                             worker.sample.data());
        if (collect) {
          collect_evidence(belief_.slice(k), worker.sample.data(), n, exponent, outside, worker.depth, worker.mass,
                           worker.belief_in_crop, worker.belief_outside, worker.outside_cells);
        }
        ArrayMap b(belief_.slice(k), N);
        ConstArrayMap sample(worker.sample.data(), N);
        if (with_prior) {
          b *= sample;
        } else {
          b = sample;
        }
        if (!gps_factor.empty()) b *= ConstArrayMap(gps_factor.data(), N);
        slice_sum[static_cast<std::size_t>(k)] = static_cast<double>(b.sum());
      }
    });
  };
  update_slices(true);
  if (calibrating) feed_estimator(frame);
  double total = 0;
  for (double x : slice_sum) total += x;
  if (!(total > 0) || !std::isfinite(total)) {
    // Belief and frame share no support that float can represent: the frame alone decides.
    update_slices(false);
    total = 0;
    for (double x : slice_sum) total += x;
    if (!(total > 0)) throw FilterError("the frame volume has no mass inside the window");
  }
  return total;
}

void SeqLocFilter::feed_estimator(const PreparedFrame& frame) {
  CalibrationEvidence evidence;
  evidence.log_outside = -frame.log_cells - config_.outside_crop_nats;
  evidence.window_cells = static_cast<double>(belief_.size());
  for (const auto& worker : impl_->workers) {
    evidence.frame_cells.merge(worker.frame_cells);
    evidence.belief_in_crop.merge(worker.belief_in_crop);
    evidence.belief_outside += worker.belief_outside;
    evidence.outside_cells += worker.outside_cells;
  }
  impl_->estimator.add(evidence);
}

SeqLocFilter::Peak SeqLocFilter::normalize(double total, const float* road_distance_m) {
  const int W = config_.width, H = config_.height, R = config_.headings;
  const std::size_t n = belief_.slice_cells();
  const auto N = static_cast<Eigen::Index>(n);
  // Normalize, MGR (b <- log((1 - eps) exp(b) + eps q) is, in probabilities, an affine blend),
  // and the argmax of every slice.
  std::vector<float> eps_q;
  if (config_.mgr) {
    eps_q = road_prior_log_q(road_distance_m, W, H, R, config_.mgr_sigma_m);
    const auto eps = static_cast<float>(config_.mgr_epsilon);
    for (float& l : eps_q) l = eps * std::exp(l);
  }
  const auto keep = static_cast<float>((config_.mgr ? 1.0 - config_.mgr_epsilon : 1.0) / total);
  std::vector<float> best_value(static_cast<std::size_t>(R), -1.0f), least_value(static_cast<std::size_t>(R));
  core::parallel_chunks(R, config_.threads, [&](int k0, int k1, int) {
    for (int k = k0; k < k1; ++k) {
      ArrayMap b(belief_.slice(k), N);
      if (config_.mgr) {
        b = b * keep + ConstArrayMap(eps_q.data(), N);
      } else {
        b *= keep;
      }
      // Value-only reductions vectorize; the argmax's index is searched in one slice below.
      best_value[static_cast<std::size_t>(k)] = b.maxCoeff();
      least_value[static_cast<std::size_t>(k)] = b.minCoeff();
    }
  });
  int k_star = 0;
  for (int k = 1; k < R; ++k) {
    if (best_value[static_cast<std::size_t>(k)] > best_value[static_cast<std::size_t>(k_star)]) k_star = k;
  }
  cached_min_ = *std::min_element(least_value.begin(), least_value.end());
  const float* star_slice = belief_.slice(k_star);
  const auto cell = static_cast<int>(std::find(star_slice, star_slice + n, best_value[static_cast<std::size_t>(k_star)]) -
                                     star_slice);
  return {cell % W, cell / W, k_star, best_value[static_cast<std::size_t>(k_star)]};
}

Pose SeqLocFilter::refine(const Peak& peak) const {
  const int R = config_.headings;
  Pose pose{static_cast<double>(peak.u), static_cast<double>(peak.v), belief_.bin_heading_deg(peak.k)};
  if (config_.pas) {
    const Pose x_hat = peak_anchored_position(belief_, peak.u, peak.v, config_.pas_radius);
    pose.u = x_hat.u;
    pose.v = x_hat.v;
  }
  if (config_.subbin_heading) {
    // Circular mean of the bin headings around th* at x*, weighted by the belief.
    double sx = 0, sy = 0;
    for (int i = -config_.subbin_half_width; i <= config_.subbin_half_width; ++i) {
      const int k = (peak.k + i + R) % R;
      const double weight = belief_.prob(peak.u, peak.v, k);
      const double h = belief_.bin_heading_deg(k) * kDegToRad;
      sx += weight * std::sin(h);
      sy += weight * std::cos(h);
    }
    pose.heading_deg = core::wrap360(std::atan2(sx, sy) / kDegToRad);
  }
  return pose;
}

}  // namespace seqloc::filter
