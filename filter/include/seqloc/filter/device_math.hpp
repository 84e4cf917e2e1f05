#pragma once
// The filter's per-cell arithmetic, written once for the CPU filter and the CUDA backend (gpu/):
// under nvcc these functions are __host__ __device__, elsewhere plain inline functions. The CPU
// filter calls them in its loops, so the test suite checks the arithmetic the kernels run even on
// machines without a GPU. Nothing here allocates, throws or reads a global.

#include <cmath>
#include <cstddef>
#include <cstdint>

#include "seqloc/core/angles.hpp"
#include "seqloc/intake/frame.hpp"

#if defined(__CUDACC__)
#define SEQLOC_HD __host__ __device__
#else
#define SEQLOC_HD
#endif

namespace seqloc::filter::math {

/// log(0) inside the filter and the smallest normal float: the intake's (intake/frame.hpp), named
/// here for the device code.
inline constexpr float kLogZeroValue = intake::kLogZero;
inline constexpr float kSmallestNormal = intake::kSmallestNormal;

/// exp(scale * (x - shift)) where x > log(0), exactly 0 where x is log(0) or -inf, and 0 where the
/// result would be subnormal (the host's detail::exp_or_zero says why).
SEQLOC_HD inline float exp_or_zero(float x, float scale, float shift) {
  const float e = x > kLogZeroValue ? ::expf(scale * (x - shift)) : 0.0f;
  return e >= kSmallestNormal ? e : 0.0f;
}

/// The window displacement (cells, u east / v south, `cell_m` metres a cell) of a move of
/// `forward_m` and `left_m` for a heading clockwise from north: forward is (sin h, cos h)
/// east/north, left is (-cos h, sin h). sin and cos of multiples of 90 degrees are not exactly 0
/// in floating point: a move that is a whole number of cells up to 1e-9 is taken as one, so that
/// it translates without blurring.
SEQLOC_HD inline void displacement_cells(double forward_m, double left_m, double heading_deg, double cell_m, double& du,
                                         double& dv) {
  const double h = heading_deg * core::kDegToRad;
  const double east = forward_m * ::sin(h) - left_m * ::cos(h);
  const double north = forward_m * ::cos(h) + left_m * ::sin(h);
  du = east / cell_m;
  dv = -north / cell_m;
  if (::fabs(du - ::round(du)) < 1e-9) du = ::round(du);
  if (::fabs(dv - ::round(dv)) < 1e-9) dv = ::round(dv);
}

/// The road prior of MGR before normalization (conventions.md section 6, step 4):
/// g(x) = exp(-d(x)^2 / (2 sigma^2)), d the distance to the nearest road: the device's copy of
/// core::road_prior_g (which host code calls), tested equal to it.
SEQLOC_HD inline double road_prior_g(double distance_m, double sigma_m) {
  return ::exp(-distance_m * distance_m / (2 * sigma_m * sigma_m));
}

/// MGR's share of a cell given g there, the sum z of g over the window's n cells and its R
/// heading bins: eps q with q = (0.9 g / z + 0.1 / n) / R, through a float log as the CPU filter
/// keeps it (road_prior_log_q).
SEQLOC_HD inline float road_prior_share(double g, double z, double n, int headings, float eps) {
  const double q = (0.9 * (z > 0 ? g / z : 0.0) + 0.1 / n) / headings;
  return eps * ::expf(static_cast<float>(::log(q)));
}

/// A bilinear translation dst(u, v) = src(u + ou, v + ov) of a sw x sh source into a dw x dh
/// destination: the integer and fractional parts of the offset and the destination cells whose
/// source point lies in [0, sw - 1] x [0, sh - 1] (the others take a fill value).
struct Translation {
  int iu = 0, iv = 0;
  float au = 0, av = 0;
  int u_lo = 0, u_hi = -1, v_lo = 0, v_hi = -1;
  int sw = 0, sh = 0;
};

SEQLOC_HD inline Translation make_translation(int sw, int sh, int dw, int dh, double ou, double ov) {
  Translation t;
  const double fu = ::floor(ou), fv = ::floor(ov);
  t.au = static_cast<float>(ou - fu);
  t.av = static_cast<float>(ov - fv);
  t.iu = static_cast<int>(fu);
  t.iv = static_cast<int>(fv);
  const int u_lo = static_cast<int>(::ceil(-ou)), u_hi = static_cast<int>(::floor(sw - 1 - ou));
  const int v_lo = static_cast<int>(::ceil(-ov)), v_hi = static_cast<int>(::floor(sh - 1 - ov));
  t.u_lo = u_lo > 0 ? u_lo : 0;
  t.u_hi = u_hi < dw - 1 ? u_hi : dw - 1;
  t.v_lo = v_lo > 0 ? v_lo : 0;
  t.v_hi = v_hi < dh - 1 ? v_hi : dh - 1;
  t.sw = sw;
  t.sh = sh;
  return t;
}

/// The translated value at destination cell (u, v), reading source cell i through `read(i)`
/// (i = row * sw + column). At the last column or row the missing neighbour has weight 0 and is
/// read clamped, as the CPU loop does.
template <class Read>
SEQLOC_HD inline float translate_at(const Translation& t, int u, int v, float fill, const Read& read) {
  if (v < t.v_lo || v > t.v_hi || u < t.u_lo || u > t.u_hi) return fill;
  const int r0 = v + t.iv, r1 = r0 + 1 < t.sh ? r0 + 1 : t.sh - 1;
  const int c0 = u + t.iu, c1 = c0 + 1 < t.sw ? c0 + 1 : c0;
  const float w00 = (1 - t.au) * (1 - t.av), w01 = t.au * (1 - t.av), w10 = (1 - t.au) * t.av, w11 = t.au * t.av;
  const std::size_t a = static_cast<std::size_t>(r0) * t.sw, b = static_cast<std::size_t>(r1) * t.sw;
  return w00 * read(a + c0) + w01 * read(a + c1) + w10 * read(b + c0) + w11 * read(b + c1);
}

/// The affine map from window cells to a frame's cells: the crop's axes are the window's turned
/// clockwise by its rotation, and one window cell is `scale` frame cells.
struct CropMap {
  double centre_u = 0, centre_v = 0;  ///< the crop's centre in window cells
  double cos_r = 1, sin_r = 0;        ///< of the crop's rotation
  double scale = 1;                   ///< frame cells per window cell
  int vw = 0, vh = 0;                 ///< the frame's size
};

/// Where a frame coordinate `at` falls along an axis of `extent` cells: inside [0, extent - 1] or
/// not (NaN is not), and if inside the cells below and above it (the last cell read twice at the
/// end) with the weight `a` of the one above.
struct CropAxis {
  int lo = 0, hi = 0;
  float a = 0;
  bool inside = false;
};
SEQLOC_HD inline CropAxis crop_axis(double at, int extent) {
  CropAxis c;
  c.inside = at >= 0 && at <= extent - 1;
  if (!c.inside) return c;
  c.lo = static_cast<int>(at);
  c.hi = c.lo + 1 < extent ? c.lo + 1 : extent - 1;
  c.a = static_cast<float>(at - c.lo);
  return c;
}

/// Bilinear in the frame's cells between two rows (starting at r0 and r1, read through `read(i)`)
/// at the columns and weights of `x`, with weight `ay` on the second row.
template <class Read>
SEQLOC_HD inline float crop_bilinear(const Read& read, std::size_t r0, std::size_t r1, const CropAxis& x, float ay) {
  return (1 - ay) * ((1 - x.a) * read(r0 + x.lo) + x.a * read(r0 + x.hi)) +
         ay * ((1 - x.a) * read(r1 + x.lo) + x.a * read(r1 + x.hi));
}

/// The frame value at window cell (u, v): bilinear in the frame's cells, read through `read(i)`
/// (i = row * vw + column); `fill` where the cell's centre lies outside the frame.
template <class Read>
SEQLOC_HD inline float crop_sample_at(const CropMap& m, int u, int v, float fill, const Read& read) {
  const double du = u - m.centre_u, dv = v - m.centre_v;
  const CropAxis x = crop_axis((m.vw - 1) / 2.0 + m.scale * (du * m.cos_r + dv * m.sin_r), m.vw);
  const CropAxis y = crop_axis((m.vh - 1) / 2.0 + m.scale * (-du * m.sin_r + dv * m.cos_r), m.vh);
  if (!(x.inside && y.inside)) return fill;
  return crop_bilinear(read, static_cast<std::size_t>(y.lo) * m.vw, static_cast<std::size_t>(y.hi) * m.vw, x, y.a);
}

/// Which two of a frame's heading bins a window heading reads: bins j0 and j1 = j0 + 1 (circular),
/// blended as (1 - a), a.
struct HeadingBlend {
  int j0 = 0, j1 = 0;
  float a = 0;
};

/// The blend for window heading `heading_deg` of a frame with `bins` bins whose crop is turned by
/// `rotation_deg`: the crop's own heading is heading - rotation, at p = that * bins / 360 bins.
/// (Host only: the kernels take the blend per bin.)
inline HeadingBlend heading_blend(double heading_deg, double rotation_deg, int bins) {
  const double p = core::wrap360(heading_deg - rotation_deg) * bins / 360.0;
  const int j0 = static_cast<int>(std::floor(p)) % bins;
  return {j0, (j0 + 1) % bins, static_cast<float>(p - std::floor(p))};
}

/// Self-calibration's coarse grid: window heading bins per coarse bin (4, or fewer where the
/// window's bins are not a multiple of 4 or would leave fewer than 4 coarse bins).
SEQLOC_HD inline int calibration_bins(int headings) {
  for (int b = 4; b > 1; b /= 2)
    if (headings % b == 0 && headings / b >= 4) return b;
  return 1;
}

/// Whether window bin k is one that coarse bins are made of, b window bins per coarse bin: every
/// bin for b = 1, else every other bin (the even ones for b = 4, the odd for b = 2).
SEQLOC_HD inline bool pooled_bin(int k, int b) { return b == 1 || k % 2 == (b / 2) % 2; }

/// The weight of window bin j b + d in coarse bin j (|d| <= b / 2): 1 at the ends, 2 between, 1
/// for b = 1 (each pooled bin standing for itself and its unpooled neighbours).
SEQLOC_HD inline float pooled_weight(int d, int b) {
  const int half = b / 2;
  return b == 1 ? 1.0f : (d == -half || d == half) ? 1.0f : 2.0f;
}

/// One slice of a belief summed over the 2 x 2 cells of coarse cell (cu, cv) (the last row or
/// column alone where the size is odd), in the order the CPU filter adds them.
SEQLOC_HD inline float pool_2x2(const float* slice, int width, int height, int cu, int cv) {
  const int u = 2 * cu, v = 2 * cv;
  const float* a = slice + static_cast<std::size_t>(v) * width;
  const bool down = v + 1 < height, right = u + 1 < width;
  const float left = down ? a[u] + a[u + width] : a[u];
  if (!right) return left;
  const float next = down ? a[u + 1] + a[u + 1 + width] : a[u + 1];
  return left + next;
}

/// A cell's terms in a DepthHistogram (selfcal/estimator.hpp): its depth d = -r clamped to
/// [0, max_depth], the bin d * per_nat (clamped to [0, last_bin]), and its weight w and w d in fixed
/// point (w >= 0 and d >= 0, so adding 0.5 before the cast rounds half up).
struct DepthTerm {
  float depth;
  int bin;
  std::int64_t weight, depth_sum;
};

SEQLOC_HD inline float clamp_depth(float r, float max_depth) {
  const float d = -r > 0.0f ? -r : 0.0f;
  return d < max_depth ? d : max_depth;
}

SEQLOC_HD inline int depth_bin(float depth, float per_nat, int last_bin) {
  const int b = static_cast<int>(depth * per_nat);
  return b < 0 ? 0 : b > last_bin ? last_bin : b;
}

SEQLOC_HD inline DepthTerm depth_term(float r, float w, float max_depth, float per_nat, int last_bin,
                                      double weight_scale, double depth_scale) {
  const float d = clamp_depth(r, max_depth);
  const double wd = w;
  return {d, depth_bin(d, per_nat, last_bin), static_cast<std::int64_t>(wd * weight_scale + 0.5),
          static_cast<std::int64_t>(wd * d * depth_scale + 0.5)};
}

}  // namespace seqloc::filter::math
