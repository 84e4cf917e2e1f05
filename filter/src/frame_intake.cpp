// Frame intake (conventions.md section 4): a backbone volume made ready for the filter, its
// tempering, the route's reference entropy for ETU, and the pose of a volume cell in the window.

#include "seqloc/filter/seqloc_filter.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <vector>

#include <Eigen/Core>

#include "internal.hpp"
#include "seqloc/core/angles.hpp"
#include "seqloc/core/thread_pool.hpp"
#include "seqloc/core/units.hpp"

namespace seqloc::filter {
namespace {

using core::kCellM;
using core::kDegToRad;

using detail::ArrayMap;
using detail::ConstArrayMap;

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
    const std::size_t best =
        static_cast<std::size_t>(std::find(f.log_prob.begin(), f.log_prob.end(), max) - f.log_prob.begin());
    f.argmax_bin = static_cast<int>(best / slice);
    f.argmax_v = static_cast<int>(best % slice / static_cast<std::size_t>(W));
    f.argmax_u = static_cast<int>(best % static_cast<std::size_t>(W));
    return;
  }
  core::parallel_chunks(blocks, chunks, [&](int b0, int b1, int) {
    const Eigen::Index start = b0 * kBlock;
    const Eigen::Index stop =
        std::min<Eigen::Index>(static_cast<Eigen::Index>(b1) * kBlock, static_cast<Eigen::Index>(cells));
    ArrayMap x(f.log_prob.data() + start, stop - start);
    x = (x > kLogZero).select(x - static_cast<float>(lse), kLogZero);
  });
  // The argmax, first in heading-major order: its value is max - lse exactly.
  const float top = max - static_cast<float>(lse);  // computed as in the pass above
  f.max_log_prob = top;
  const std::size_t best =
      static_cast<std::size_t>(std::find(f.log_prob.begin(), f.log_prob.end(), top) - f.log_prob.begin());
  f.argmax_bin = static_cast<int>(static_cast<std::size_t>(best) / slice);
  f.argmax_v = static_cast<int>(static_cast<std::size_t>(best) % slice / static_cast<std::size_t>(W));
  f.argmax_u = static_cast<int>(static_cast<std::size_t>(best) % static_cast<std::size_t>(W));
}

/// Bins j0 .. j1 of an (H, W, N) volume into heading-major `log_prob` (N slices of H x W), one
/// source row at a time (it stays in cache). A float16 row's bins j0 .. j1 are converted first
/// (halves_to_floats, eight values to an instruction) into a float copy, which the gather reads.
void transpose_bins(const FrameVolume& volume, int j0, int j1, float* log_prob) {
  const int H = volume.height, W = volume.width, N = volume.bins;
  const std::size_t slice = static_cast<std::size_t>(H) * W, n = static_cast<std::size_t>(N);
  const auto nb = static_cast<std::size_t>(j1 - j0);
  std::vector<float> converted(volume.type == VolumeType::float16 ? static_cast<std::size_t>(W) * nb : 0);
  for (int v = 0; v < H; ++v) {
    const std::size_t row = static_cast<std::size_t>(v) * W * n + static_cast<std::size_t>(j0);
    // Bin j0 of cell u of this row is at src_row[u * stride].
    const float* src_row = converted.data();
    std::size_t stride = nb;
    if (volume.type == VolumeType::float32) {
      src_row = static_cast<const float*>(volume.data) + row;
      stride = n;
    } else {
      const std::uint16_t* halves = static_cast<const std::uint16_t*>(volume.data) + row;
      for (std::size_t u = 0; u < static_cast<std::size_t>(W); ++u) {
        halves_to_floats({halves + u * n, nb}, {converted.data() + u * nb, nb});
      }
    }
    for (int j = j0; j < j1; ++j) {
      float* dst = log_prob + static_cast<std::size_t>(j) * slice + static_cast<std::size_t>(v) * W;
      const float* src = src_row + (j - j0);
      for (int u = 0; u < W; ++u) dst[u] = src[static_cast<std::size_t>(u) * stride];
    }
  }
}

}  // namespace

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
  // Per chunk of bins, in parallel: convert and transpose (H, W, N) to heading-major, check, map
  // -inf to kLogZero and find the chunk's maximum.
  constexpr float kInf = std::numeric_limits<float>::infinity();
  const bool is_prob = volume.values == VolumeValues::prob;
  const int chunks = std::max(1, std::min(threads, N));
  std::vector<float> chunk_max(static_cast<std::size_t>(chunks), -kInf);
  std::vector<char> chunk_bad(static_cast<std::size_t>(chunks), 0);
  core::parallel_chunks(N, chunks, [&](int j0, int j1, int t) {
    transpose_bins(volume, j0, j1, f.log_prob.data());
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

}  // namespace seqloc::filter
