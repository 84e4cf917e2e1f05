#include "seqloc/matcher/calibration.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <limits>
#include <sstream>
#include <stdexcept>
#include <utility>

#include <Eigen/Core>

#include "seqloc/core/error.hpp"
#include "seqloc/core/thread_pool.hpp"

namespace seqloc::matcher {
namespace {

using ConstArrayMap = Eigen::Map<const Eigen::ArrayXf>;

// Offset of (row, column, bin) in a window of side x side x depth, row-major.
std::size_t window_index(int row, int column, int bin, int side, int depth) {
  return static_cast<std::size_t>((static_cast<long long>(row) * side + column) * depth + bin);
}

// taps[index] for an index computed in int (offsets from a kernel's centre).
double tap(const std::vector<double>& taps, int index) { return taps[static_cast<std::size_t>(index)]; }

// log sum exp(values / temperature), accumulated in double over blocks.
double log_sum_exp(std::span<const float> values, float top, double temperature) {
  constexpr std::size_t kBlock = 1 << 14;
  const auto inverse = static_cast<float>(1.0 / temperature);
  double sum = 0;
  for (std::size_t start = 0; start < values.size(); start += kBlock) {
    const std::size_t n = std::min(kBlock, values.size() - start);
    const ConstArrayMap block(values.data() + start, static_cast<Eigen::Index>(n));
    sum += static_cast<double>(((block - top) * inverse).exp().sum());
  }
  return static_cast<double>(top) / temperature + std::log(sum);
}

// values[i] = f(values[i]) for an Eigen array expression f, over [0, n) shared among `threads`
// threads. Eigen computes exp and log differently in a vectorized body and in the scalar head
// and tail it peels off by address, so each block of values is copied into an aligned buffer of
// whole packets first: every value takes the same path wherever it lies, and the results are the
// same bits whatever the buffer's address and the number of threads.
template <class F>
void vectorized(float* values, std::size_t n, int threads, F&& f) {
  constexpr std::size_t kBlock = 4096;
  const std::size_t blocks = (n + kBlock - 1) / kBlock;
  core::parallel_chunks(blocks, threads, [&](std::size_t k0, std::size_t k1, int) {
    Eigen::ArrayXf buffer(static_cast<Eigen::Index>(kBlock));  // Eigen aligns its own storage
    for (std::size_t k = k0; k < k1; ++k) {
      const std::size_t start = k * kBlock, m = std::min(kBlock, n - start);
      std::copy(values + start, values + start + m, buffer.data());
      std::fill(buffer.data() + m, buffer.data() + kBlock, 0.0f);
      buffer = f(buffer);
      std::copy(buffer.data(), buffer.data() + m, values + start);
    }
  });
}

// One axis of a blur over `count` blocks of `block` contiguous values: out block i = sum_j taps[j]
// * in block (i + j - radius), blocks past either end left out, for the values [b0, b1) of each
// block (`in` holds blocks `in_block` apart). Whole runs of a block at a time, so the inner loop
// runs over contiguous memory.
void convolve_blocks(float* out, std::size_t block, const float* in, std::size_t in_block, int count, std::size_t b0,
                     std::size_t b1, const std::vector<float>& taps) {
  const int radius = static_cast<int>(taps.size() / 2);
  for (int i = 0; i < count; ++i) {
    float* o = out + static_cast<std::size_t>(i) * block;
    std::fill(o + b0, o + b1, 0.0f);
    for (int j = -radius; j <= radius; ++j) {
      const int source = i + j;
      if (source < 0 || source >= count) continue;
      const float w = taps[static_cast<std::size_t>(j) + static_cast<std::size_t>(radius)];
      const float* x = in + static_cast<std::size_t>(source) * in_block;
      for (std::size_t b = b0; b < b1; ++b) o[b] += w * x[b];
    }
  }
}

// The same blur across `count` blocks in place, for the values [b0, b1) of each block, through a
// copy of a strip of at most 1,024 values per block at a time (a few hundred KB, not the volume).
void convolve_blocks_in_place(float* data, int count, std::size_t block, std::size_t b0, std::size_t b1,
                              const std::vector<float>& taps) {
  constexpr std::size_t kStrip = 1024;
  std::vector<float> strip;
  for (std::size_t s0 = b0; s0 < b1; s0 += kStrip) {
    const std::size_t w = std::min(kStrip, b1 - s0);
    strip.resize(static_cast<std::size_t>(count) * w);
    for (int i = 0; i < count; ++i) {
      const float* from = data + static_cast<std::size_t>(i) * block + s0;
      std::copy(from, from + w, strip.begin() + static_cast<std::ptrdiff_t>(static_cast<std::size_t>(i) * w));
    }
    convolve_blocks(data + s0, block, strip.data(), w, count, 0, w, taps);
  }
}

// Convolves each of `lines` contiguous lines of `count` values circularly with `taps` (centred),
// through a copy of the line padded with its own wrapped ends.
void convolve_circular(float* data, std::vector<float>& padded, std::size_t lines, int count,
                       const std::vector<float>& taps) {
  const int radius = static_cast<int>(taps.size() / 2);
  padded.resize(static_cast<std::size_t>(count) + taps.size() - 1);  // count + 2 radius
  for (std::size_t line = 0; line < lines; ++line) {
    float* x = data + line * static_cast<std::size_t>(count);
    for (int i = 0; i < count + 2 * radius; ++i)
      padded[static_cast<std::size_t>(i)] = x[((i - radius) % count + count) % count];
    // Tap by tap over the whole line (the same sum, in the same order, per value; the inner loop
    // runs over contiguous memory).
    std::fill(x, x + count, 0.0f);
    for (int j = 0; j <= 2 * radius; ++j) {
      const float w = taps[static_cast<std::size_t>(j)];
      const float* in = padded.data() + j;
      for (int i = 0; i < count; ++i) x[i] += w * in[i];
    }
  }
}

std::vector<float> float_taps(double sigma) {
  const auto taps = gaussian_taps(sigma);
  return {taps.begin(), taps.end()};
}

// The first step of a calibration, either layout. The identity: the volume becomes its
// log-softmax (exact in the log domain) and true is returned. Otherwise, in place and in float,
// p = exp(v - top): the volume is the only large buffer (a 128 x 128 x 256 one is 16 MB). Scores
// more than 40 nats under the top count as 40 under it: e^-40 times the smallest tap of three
// blurs (sigma <= 64) stays a normal float, so no denormal arises (its arithmetic is two orders of
// magnitude slower, and threads that flush denormals to zero, as OpenCV's callers may, would give
// other bits); a probability of e^-40 relative to the peak is nothing beside any floor.
bool start_calibration(std::span<float> volume, const VolumeCalibration& c, int threads) {
  const float top = ConstArrayMap(volume.data(), static_cast<Eigen::Index>(volume.size())).maxCoeff();
  if (c.floor == 0 && c.blur_bins == 0 && c.blur_cells == 0) {
    const double lse = log_sum_exp(volume, top, 1.0);
    for (float& v : volume) v = static_cast<float>(static_cast<double>(v) - lse);
    return true;
  }
  vectorized(volume.data(), volume.size(), threads,
             [top](const Eigen::ArrayXf& x) { return ((x - top).max(-40.0f)).exp().eval(); });
  return false;
}

// The last step: the blurred probabilities (summing to `sum`) mixed with the floor a, back to logs.
void finish_calibration(std::span<float> volume, double a, double sum, int threads) {
  const auto scale = static_cast<float>((1 - a) / sum);
  const auto uniform = static_cast<float>(a / static_cast<double>(volume.size()));
  vectorized(volume.data(), volume.size(), threads, [scale, uniform](const Eigen::ArrayXf& x) {
    return (x * scale + uniform).max(std::numeric_limits<float>::min()).log().eval();
  });
}

}  // namespace

void VolumeCalibration::validate() const {
  auto fail = [](const char* field, double value, const char* constraint) {
    std::ostringstream s;
    s << "calibration: " << field << " = " << value << ": " << constraint;
    throw UsageError(s.str());
  };
  if (!(blur_cells >= 0 && blur_cells <= 64)) fail("blur_cells", blur_cells, "must be in [0, 64]");
  if (!(blur_bins >= 0 && blur_bins <= 64)) fail("blur_bins", blur_bins, "must be in [0, 64]");
  if (!(floor >= 0 && floor < 1)) fail("floor", floor, "must be in [0, 1)");
}

std::vector<double> gaussian_taps(double sigma) {
  if (!(sigma > 0)) return {1.0};
  const int radius = static_cast<int>(std::ceil(3 * sigma));
  std::vector<double> taps(static_cast<std::size_t>(2 * radius + 1));
  double sum = 0;
  for (std::size_t k = 0; k < taps.size(); ++k) {
    const double i = static_cast<double>(k) - radius;
    taps[k] = std::exp(-0.5 * (i / sigma) * (i / sigma));
    sum += taps[k];
  }
  for (auto& w : taps) w /= sum;
  return taps;
}

void calibrate_volume(std::span<float> volume, int height, int width, int bins, const VolumeCalibration& c,
                      int threads) {
  c.validate();
  const std::size_t cells = volume.size();
  if (cells != static_cast<std::size_t>(height) * static_cast<std::size_t>(width) * static_cast<std::size_t>(bins) ||
      cells == 0) {
    throw UsageError("calibrate_volume: the volume's size is not height * width * bins");
  }
  if (start_calibration(volume, c, threads)) return;
  float* p = volume.data();
  const auto H = static_cast<std::size_t>(height), W = static_cast<std::size_t>(width),
             N = static_cast<std::size_t>(bins);
  if (c.blur_bins > 0) {
    const auto taps = float_taps(c.blur_bins);
    core::parallel_chunks(H * W, threads, [&](std::size_t l0, std::size_t l1, int) {
      std::vector<float> padded;
      convolve_circular(p + l0 * N, padded, l1 - l0, bins, taps);
    });
  }
  if (c.blur_cells > 0) {
    const auto taps = float_taps(c.blur_cells);
    // Along u: each row is `width` blocks of N headings (rows shared among threads).
    core::parallel_chunks(H, threads, [&](std::size_t r0, std::size_t r1, int) {
      std::vector<float> row(W * N);
      for (std::size_t r = r0; r < r1; ++r) {
        float* out = p + r * W * N;
        std::copy(out, out + W * N, row.begin());
        convolve_blocks(out, N, row.data(), N, width, 0, N, taps);
      }
    });
    // Along v: `height` blocks of whole rows (runs of each row shared among threads).
    core::parallel_chunks(W * N, threads, [&](std::size_t b0, std::size_t b1, int) {
      convolve_blocks_in_place(p, height, W * N, b0, b1, taps);
    });
  }
  // A plain loop: a vectorized reduction would group the terms by the buffer's address.
  double sum = 0;
  for (std::size_t i = 0; i < cells; ++i) sum += static_cast<double>(p[i]);
  finish_calibration(volume, c.floor, sum, threads);
}

namespace {

// The blur across heading bins of a heading-major volume: slice j = sum_k taps[k] slice (j + k -
// radius), circularly, each value's terms in the order convolve_circular adds them. Cells in
// strips of 1,024, all bins of a strip copied out first.
void blur_bins_heading_major(float* p, int bins, std::size_t slice, const std::vector<float>& taps, int threads) {
  constexpr std::size_t kStrip = 1024;
  const int radius = static_cast<int>(taps.size() / 2);
  const std::size_t strips = (slice + kStrip - 1) / kStrip;
  const auto N = static_cast<std::size_t>(bins);
  core::parallel_chunks(strips, threads, [&](std::size_t s0, std::size_t s1, int) {
    std::vector<float> strip(N * kStrip);
    for (std::size_t s = s0; s < s1; ++s) {
      const std::size_t c0 = s * kStrip, w = std::min(kStrip, slice - c0);
      for (std::size_t j = 0; j < N; ++j) std::copy(p + j * slice + c0, p + j * slice + c0 + w, strip.data() + j * w);
      for (int j = 0; j < bins; ++j) {
        float* o = p + static_cast<std::size_t>(j) * slice + c0;
        std::fill(o, o + w, 0.0f);
        for (int k = 0; k <= 2 * radius; ++k) {
          const float weight = taps[static_cast<std::size_t>(k)];
          const auto source = static_cast<std::size_t>(((j + k - radius) % bins + bins) % bins);
          const float* x = strip.data() + source * w;
          for (std::size_t c = 0; c < w; ++c) o[c] += weight * x[c];
        }
      }
    }
  });
}

// The blur along u of every row of a heading-major volume (`rows` rows of `width`), each value's
// terms in the order convolve_blocks adds them, values past either end left out.
void blur_rows(float* p, std::size_t rows, int width, const std::vector<float>& taps, int threads) {
  const int radius = static_cast<int>(taps.size() / 2);
  core::parallel_chunks(rows, threads, [&](std::size_t r0, std::size_t r1, int) {
    std::vector<float> row(static_cast<std::size_t>(width));
    for (std::size_t r = r0; r < r1; ++r) {
      float* o = p + r * static_cast<std::size_t>(width);
      std::copy(o, o + width, row.begin());
      std::fill(o, o + width, 0.0f);
      for (int j = -radius; j <= radius; ++j) {
        const float weight = taps[static_cast<std::size_t>(j + radius)];
        const int u0 = std::max(0, -j), u1 = std::min(width, width - j);
        for (int u = u0; u < u1; ++u) o[u] += weight * row[static_cast<std::size_t>(u + j)];
      }
    }
  });
}

}  // namespace

void calibrate_heading_major(std::span<float> volume, int bins, int height, int width, const VolumeCalibration& c,
                             int threads) {
  c.validate();
  const std::size_t cells = volume.size();
  const std::size_t slice = static_cast<std::size_t>(height) * static_cast<std::size_t>(width);
  if (cells != slice * static_cast<std::size_t>(bins) || cells == 0) {
    throw UsageError("calibrate_heading_major: the volume's size is not bins * height * width");
  }
  if (start_calibration(volume, c, threads)) return;
  float* p = volume.data();
  if (c.blur_bins > 0) blur_bins_heading_major(p, bins, slice, float_taps(c.blur_bins), threads);
  if (c.blur_cells > 0) {
    const auto taps = float_taps(c.blur_cells);
    blur_rows(p, static_cast<std::size_t>(bins) * static_cast<std::size_t>(height), width, taps, threads);
    // Along v: each slice is `height` blocks of a row.
    core::parallel_chunks(static_cast<std::size_t>(bins), threads, [&](std::size_t j0, std::size_t j1, int) {
      for (std::size_t j = j0; j < j1; ++j) {
        convolve_blocks_in_place(p + j * slice, height, static_cast<std::size_t>(width), 0,
                                 static_cast<std::size_t>(width), taps);
      }
    });
  }
  // Eight sums, value i in sum i % 8, then added in order: a grouping set by the index alone (not
  // the buffer's address), which vectorizes.
  std::array<double, 8> lanes{};
  const std::size_t whole = cells / lanes.size() * lanes.size();
  for (std::size_t i = 0; i < whole; i += lanes.size()) {
    for (std::size_t k = 0; k < lanes.size(); ++k) lanes[k] += static_cast<double>(p[i + k]);
  }
  for (std::size_t i = whole; i < cells; ++i) lanes[i % lanes.size()] += static_cast<double>(p[i]);
  double sum = 0;
  for (const double lane : lanes) sum += lane;
  finish_calibration(volume, c.floor, sum, threads);
}

CalibrationFit::CalibrationFit() : CalibrationFit(Grid{}) {}

CalibrationFit::CalibrationFit(Grid grid) : grid_(std::move(grid)) {
  for (double s : grid_.blur_cells)
    radius_cells_ = std::max(radius_cells_, static_cast<int>(gaussian_taps(s).size() / 2));
  for (double s : grid_.blur_bins) radius_bins_ = std::max(radius_bins_, static_cast<int>(gaussian_taps(s).size() / 2));
}

void CalibrationFit::add(std::span<const float> scores, int height, int width, int bins, int true_v, int true_u,
                         int true_bin) {
  if (true_v < 0 || true_u < 0 || true_v >= height || true_u >= width) {
    ++skipped_;
    return;
  }
  Frame frame;
  frame.log_cells = std::log(static_cast<double>(scores.size()));
  const float top = *std::max_element(scores.begin(), scores.end());
  for (double t : grid_.temperatures) frame.log_z.push_back(log_sum_exp(scores, top, t));
  const int rc = radius_cells_, rb = radius_bins_;
  const int side = 2 * rc + 1, depth = 2 * rb + 1;
  frame.window.assign(static_cast<std::size_t>(side) * static_cast<std::size_t>(side) * static_cast<std::size_t>(depth),
                      std::numeric_limits<float>::quiet_NaN());
  for (int dv = -rc; dv <= rc; ++dv) {
    for (int du = -rc; du <= rc; ++du) {
      const int v = true_v + dv, u = true_u + du;
      if (v < 0 || u < 0 || v >= height || u >= width) continue;
      for (int db = -rb; db <= rb; ++db) {
        const int b = (((true_bin + db) % bins) + bins) % bins;
        const std::size_t from =
            (static_cast<std::size_t>(v) * static_cast<std::size_t>(width) + static_cast<std::size_t>(u)) *
                static_cast<std::size_t>(bins) +
            static_cast<std::size_t>(b);
        const std::size_t to = window_index(dv + rc, du + rc, db + rb, side, depth);
        frame.window[to] = scores[from];
      }
    }
  }
  frames_.push_back(std::move(frame));
}

double CalibrationFit::blurred_at_truth(const Frame& frame, std::size_t t, double blur_cells, double blur_bins) const {
  const auto taps_xy = gaussian_taps(blur_cells), taps_b = gaussian_taps(blur_bins);
  const int rxy = static_cast<int>(taps_xy.size() / 2), rb = static_cast<int>(taps_b.size() / 2);
  const int side = 2 * radius_cells_ + 1, depth = 2 * radius_bins_ + 1;
  const double temperature = grid_.temperatures[t], log_z = frame.log_z[t];
  double value = 0;
  for (int dv = -rxy; dv <= rxy; ++dv) {
    for (int du = -rxy; du <= rxy; ++du) {
      for (int db = -rb; db <= rb; ++db) {
        const float s =
            frame.window[window_index(dv + radius_cells_, du + radius_cells_, db + radius_bins_, side, depth)];
        if (std::isnan(s)) continue;  // outside the volume
        value += tap(taps_xy, dv + rxy) * tap(taps_xy, du + rxy) * tap(taps_b, db + rb) *
                 std::exp(static_cast<double>(s) / temperature - log_z);
      }
    }
  }
  return value;
}

double CalibrationFit::mean_nll(double temperature, const VolumeCalibration& c) const {
  const auto it = std::find(grid_.temperatures.begin(), grid_.temperatures.end(), temperature);
  if (it == grid_.temperatures.end()) throw UsageError("mean_nll: the temperature is not on the grid");
  const auto t = static_cast<std::size_t>(it - grid_.temperatures.begin());
  double total = 0;
  for (const auto& frame : frames_) {
    const double p = blurred_at_truth(frame, t, c.blur_cells, c.blur_bins);
    total -= std::log((1 - c.floor) * p + c.floor * std::exp(-frame.log_cells));
  }
  return frames_.empty() ? 0.0 : total / static_cast<double>(frames_.size());
}

CalibrationFit::Result CalibrationFit::best() const {
  Result result;
  result.frames = frames_.size();
  result.skipped = skipped_;
  result.nll = std::numeric_limits<double>::infinity();
  for (const auto& frame : frames_) result.uniform_nll += frame.log_cells;
  if (!frames_.empty()) result.uniform_nll /= static_cast<double>(frames_.size());
  std::vector<double> blurred(frames_.size());
  for (std::size_t t = 0; t < grid_.temperatures.size(); ++t) {
    for (double bc : grid_.blur_cells) {
      for (double bb : grid_.blur_bins) {
        for (std::size_t f = 0; f < frames_.size(); ++f) blurred[f] = blurred_at_truth(frames_[f], t, bc, bb);
        for (double a : grid_.floors) {
          double total = 0;
          for (std::size_t f = 0; f < frames_.size(); ++f) {
            total -= std::log((1 - a) * blurred[f] + a * std::exp(-frames_[f].log_cells));
          }
          const double nll = frames_.empty() ? 0.0 : total / static_cast<double>(frames_.size());
          if (nll < result.nll) {
            result.nll = nll;
            result.temperature = grid_.temperatures[t];
            result.calibration = {bc, bb, a};
          }
        }
      }
    }
  }
  return result;
}

}  // namespace seqloc::matcher
