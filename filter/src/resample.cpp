// The resampling kernels the online filter, the offline baseline and the smoother share: the
// odometry's displacement, bilinear translation, a frame sampled into a window slice, the warp of
// a whole belief.

#include <algorithm>
#include <cmath>
#include <utility>

#include <Eigen/Core>

#include "internal.hpp"
#include "seqloc/core/angles.hpp"
#include "seqloc/core/thread_pool.hpp"
#include "seqloc/core/units.hpp"

namespace seqloc::filter {
namespace {

using core::kCellM;
using core::kDegToRad;

// The columns of window row v whose cells may fall inside the frame under `map`, widened by a cell
// on each side: every cell outside [lo, hi] is outside the frame, whatever the rounding, so the
// exact sampler need only see the cells within (an empty range has hi < lo).
std::pair<int, int> inside_columns(const math::CropMap& m, int v, int width) {
  // x and y of math::crop_sample_at are affine in u: x = x0 + dx * u, y = y0 + dy * u.
  const double dv = v - m.centre_v;
  const double x0 = (m.vw - 1) / 2.0 + m.scale * (-m.centre_u * m.cos_r + dv * m.sin_r), dx = m.scale * m.cos_r;
  const double y0 = (m.vh - 1) / 2.0 + m.scale * (m.centre_u * m.sin_r + dv * m.cos_r), dy = -m.scale * m.sin_r;
  double lo = 0, hi = width - 1;
  const auto within = [&](double at0, double slope, double extent) {
    if (std::abs(slope) < 1e-12) {
      if (at0 < -1 || at0 > extent + 1) hi = lo - 1;  // the whole row is outside
      return;
    }
    const double a = (0 - at0) / slope, b = (extent - at0) / slope;
    lo = std::max(lo, std::min(a, b));
    hi = std::min(hi, std::max(a, b));
  };
  within(x0, dx, m.vw - 1);
  within(y0, dy, m.vh - 1);
  if (hi < lo) return {0, -1};
  return {static_cast<int>(std::floor(lo)) - 1, std::min(static_cast<int>(std::ceil(hi)) + 1, width - 1)};
}

bool is_power_of_two(double x) {
  int exponent = 0;
  return x > 0 && std::frexp(x, &exponent) == 0.5;
}

// math::crop_sample_at for every cell of a window slice where the crop is not turned and its scale
// is a power of two (self-calibration's coarse grid, at twice the frame's cells): x depends on u
// alone and y on v alone, each exactly as crop_sample_at computes it (scale * du is exact), so the
// columns' math::crop_axis is found once per slice, and each cell is crop_sample_at's
// math::crop_bilinear: the same values.
void sample_axis_aligned(const float* values, const math::CropMap& m, int width, int height, float fill, float* out) {
  std::vector<math::CropAxis> columns(static_cast<std::size_t>(width));
  for (int u = 0; u < width; ++u) {
    columns[static_cast<std::size_t>(u)] = math::crop_axis((m.vw - 1) / 2.0 + m.scale * (u - m.centre_u), m.vw);
  }
  const auto read = [values](std::size_t i) { return values[i]; };
  for (int v = 0; v < height; ++v) {
    float* row = out + static_cast<std::size_t>(v) * width;
    const math::CropAxis y = math::crop_axis((m.vh - 1) / 2.0 + m.scale * (v - m.centre_v), m.vh);
    if (!y.inside) {
      std::fill(row, row + width, fill);
      continue;
    }
    const std::size_t r0 = static_cast<std::size_t>(y.lo) * m.vw, r1 = static_cast<std::size_t>(y.hi) * m.vw;
    for (int u = 0; u < width; ++u) {
      const math::CropAxis& x = columns[static_cast<std::size_t>(u)];
      row[u] = x.inside ? math::crop_bilinear(read, r0, r1, x, y.a) : fill;
    }
  }
}

}  // namespace

void displacement_cells(const Odometry& o, double heading_deg, double& du, double& dv) {
  math::displacement_cells(o.forward_m, o.left_m, heading_deg, kCellM, du, dv);
}

void translate(const float* src, int sw, int sh, float* dst, int dw, int dh, double ou, double ov, float fill) {
  const math::Translation t = math::make_translation(sw, sh, dw, dh, ou, ov);
  const int iu = t.iu, u_lo = t.u_lo, u_hi = t.u_hi;
  const float w00 = (1 - t.au) * (1 - t.av), w01 = t.au * (1 - t.av), w10 = (1 - t.au) * t.av, w11 = t.au * t.av;
  for (int v = 0; v < dh; ++v) {
    float* out = dst + static_cast<std::size_t>(v) * dw;
    if (v < t.v_lo || v > t.v_hi || u_lo > u_hi) {
      std::fill(out, out + dw, fill);
      continue;
    }
    const int r0 = v + t.iv, r1 = std::min(r0 + 1, sh - 1);
    const float* a = src + static_cast<std::size_t>(r0) * sw + iu;
    const float* b = src + static_cast<std::size_t>(r1) * sw + iu;
    std::fill(out, out + u_lo, fill);
    // Columns whose right neighbour exists (math::translate_at, unrolled so that it vectorizes);
    // the last valid one may need the clamp.
    const int u_inner = std::min(u_hi, sw - 2 - iu);
    for (int u = u_lo; u <= u_inner; ++u) out[u] = w00 * a[u] + w01 * a[u + 1] + w10 * b[u] + w11 * b[u + 1];
    for (int u = std::max(u_lo, u_inner + 1); u <= u_hi; ++u)
      out[u] = w00 * a[u] + w10 * b[u] + w01 * a[u] + w11 * b[u];
    std::fill(out + u_hi + 1, out + dw, fill);
  }
}

void sample_slice(const float* values, int bins, int vh, int vw, double cell_m, const CropPose& crop,
                  double heading_deg, int width, int height, float fill, std::vector<float>& blend_buffer, float* out) {
  // Heading: the crop's own heading of window heading h is h - rotation.
  const auto [j0, j1, a] = math::heading_blend(heading_deg, crop.rotation_deg, bins);
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
  // General affine map from window cells to volume cells.
  const double r = crop.rotation_deg * kDegToRad;
  const math::CropMap map{crop.centre_u, crop.centre_v, std::cos(r), std::sin(r), scale, vw, vh};
  if (crop.rotation_deg == 0.0 && is_power_of_two(scale)) {
    sample_axis_aligned(blended, map, width, height, fill, out);
    return;
  }
  const auto read = [blended](std::size_t i) { return blended[i]; };
  for (int v = 0; v < height; ++v) {
    float* row = out + static_cast<std::size_t>(v) * width;
    const auto [u_lo, u_hi] = inside_columns(map, v, width);
    std::fill(row, row + std::max(u_lo, 0), fill);
    for (int u = std::max(u_lo, 0); u <= u_hi; ++u) row[u] = math::crop_sample_at(map, u, v, fill, read);
    std::fill(row + std::max(u_hi + 1, 0), row + width, fill);
  }
}

void warp_volume(const BeliefVolume& in, BeliefVolume& out, const Odometry& odometry, float fill, int threads) {
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

}  // namespace seqloc::filter
