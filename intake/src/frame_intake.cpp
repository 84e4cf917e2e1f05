// Frame intake (conventions.md section 4): a backbone volume made ready for the filter, and its
// tempering.

#include "seqloc/intake/frame.hpp"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstring>
#include <limits>
#include <optional>
#include <sstream>
#include <vector>

#include <Eigen/Core>

#include "frame_intake_simd.hpp"
#include "seqloc/core/thread_pool.hpp"

namespace seqloc::intake {

void exp_or_zero(const float* x, std::size_t n, float scale, float shift, float* out) {
  constexpr std::size_t kBlock = 1024;
  Eigen::Array<float, static_cast<Eigen::Index>(kBlock), 1> y;
  for (std::size_t start = 0; start < n; start += kBlock) {
    const std::size_t len = std::min(kBlock, n - start);
    const float* in = x + start;
    y.head(static_cast<Eigen::Index>(len)) =
        (scale * (Eigen::Map<const Eigen::ArrayXf>(in, static_cast<Eigen::Index>(len)) - shift)).exp();
    for (std::size_t i = 0; i < len; ++i) {
      const float e = y[static_cast<Eigen::Index>(i)];
      out[start + i] = in[i] > kLogZero && e >= kSmallestNormal ? e : 0.0f;
    }
  }
}

namespace {

using core::FrameVolume;
using core::half_to_float;
using core::halves_to_floats;
using core::VolumeType;
using core::VolumeValues;

/// A float buffer as an Eigen array, in place.
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
      exp_or_zero(x.data(), static_cast<std::size_t>(len), 1.0f, max, eb.data());
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

/// x as the filter's log-probabilities, in place, in loops that vectorize: logs of probabilities,
/// values at or below kLogZero (-inf, zero probabilities) as kLogZero, then raised to `power`.
/// Returns whether a value was bad (NaN, +inf, a negative probability); `check` false: the values
/// are known to be good (they were checked before).
bool to_log_prob(float* x, std::size_t n, bool is_prob, float power, bool check = true) {
  ArrayMap m(x, static_cast<Eigen::Index>(n));
  if (is_prob && check) {
    // A negative number or NaN has the sign bit or an all-ones exponent with a mantissa; +inf
    // the all-ones exponent: every bad value's pattern is 0x7F800000 or more.
    std::uint32_t bad = 0;
    for (std::size_t i = 0; i < n; ++i) {
      std::uint32_t bits = 0;
      std::memcpy(&bits, x + i, sizeof bits);
      bad |= static_cast<std::uint32_t>(bits >= 0x7F800000u && bits != 0x80000000u);  // -0 is a zero
    }
    if (bad != 0) return true;
  }
  if (is_prob) {
    m = (m > 0).select(m.log(), kLogZero);
  } else if (check) {
    // NaN and +inf: 0x7F800000 .. 0x7FFFFFFF, or a negative NaN above 0xFF800000 (-inf).
    std::uint32_t bad = 0;
    for (std::size_t i = 0; i < n; ++i) {
      std::uint32_t bits = 0;
      std::memcpy(&bits, x + i, sizeof bits);
      bad |=
          static_cast<std::uint32_t>(bits - 0x7F800000u < 0x00800000u) | static_cast<std::uint32_t>(bits > 0xFF800000u);
    }
    if (bad != 0) return true;
  }
  // Everything at or below kLogZero is a zero to every reader of the frame. (A loop, not Eigen
  // 3.4's select, which does not vectorize.)
  for (std::size_t i = 0; i < n; ++i) x[i] = x[i] > kLogZero ? x[i] * power : kLogZero;
  return false;
}

/// Bins j0 .. j1 of every cell of row v of a volume as floats, as given, in `row` ([u][j - j0]):
/// float16 converted (halves_to_floats, eight values to an instruction).
void convert_row(const FrameVolume& volume, int v, int j0, int j1, float* row) {
  const std::size_t n = static_cast<std::size_t>(volume.bins), nb = static_cast<std::size_t>(j1 - j0);
  const auto W = static_cast<std::size_t>(volume.width);
  const std::size_t first = static_cast<std::size_t>(v) * W * n + static_cast<std::size_t>(j0);
  if (volume.type == VolumeType::float16) {
    const std::uint16_t* halves = static_cast<const std::uint16_t*>(volume.data) + first;
    if (nb == n) {
      halves_to_floats({halves, W * n}, {row, W * n});
    } else {
      for (std::size_t u = 0; u < W; ++u) halves_to_floats({halves + u * n, nb}, {row + u * nb, nb});
    }
  } else {
    const float* floats = static_cast<const float*>(volume.data) + first;
    for (std::size_t u = 0; u < W; ++u) std::copy(floats + u * n, floats + u * n + nb, row + u * nb);
  }
}

/// convert_row, then the values as the filter's log-probabilities raised to `power` (to_log_prob).
/// Returns whether a value was bad (NaN, +inf, a negative probability); the row is then not to be
/// used.
bool read_row(const FrameVolume& volume, int v, int j0, int j1, float power, float* row) {
  convert_row(volume, v, j0, j1, row);
  const std::size_t len = static_cast<std::size_t>(volume.width) * static_cast<std::size_t>(j1 - j0);
  return to_log_prob(row, len, volume.values == VolumeValues::prob, power);
}

/// The log-softmax's sums of each heading bin, in the manner of an online softmax: with M_j the
/// largest value of bin j seen so far, sum_j = sum e and ex_j = sum e x, e = exp(x - M_j) (zero
/// cells and values under the smallest normal float count 0), rescaled whenever M_j grows. Each
/// bin's sums see its cells in the same order whichever worker holds it, so the frame is the same
/// for any number of threads.
struct BinSums {
  Eigen::ArrayXf max;      ///< M_j of bins j0 .. j1
  Eigen::ArrayXd sum, ex;  ///< of bins j0 .. j1
  Eigen::ArrayXf row_max, row_sum, row_ex, padded, e;

  explicit BinSums(int bins)
      : max(Eigen::ArrayXf::Constant(bins, kLogZero)),
        sum(Eigen::ArrayXd::Zero(bins)),
        ex(Eigen::ArrayXd::Zero(bins)),
        row_max(bins),
        row_sum(bins),
        row_ex(bins),
        padded(Eigen::ArrayXf::Zero((bins + 7) / 8 * 8)),
        e(padded.size()) {}

  /// Adds a row of cells ([u][j - j0], `width` cells).
  void add_row(const float* row, int width) {
    const Eigen::Index nb = max.size();
    row_max = ConstArrayMap(row, nb);
    for (int u = 1; u < width; ++u) row_max = row_max.max(ConstArrayMap(row + static_cast<std::size_t>(u) * nb, nb));
    for (Eigen::Index j = 0; j < nb; ++j) {
      if (row_max[j] > max[j]) {
        const double rescale = max[j] > kLogZero ? std::exp(double{max[j]} - row_max[j]) : 0.0;
        sum[j] *= rescale;
        ex[j] *= rescale;
        max[j] = row_max[j];
      }
    }
    row_sum.setZero();
    row_ex.setZero();
    float* __restrict s = row_sum.data();
    float* __restrict sx = row_ex.data();
    const float* __restrict ex_u = e.data();
    for (int u = 0; u < width; ++u) {
      const float* __restrict x = row + static_cast<std::size_t>(u) * nb;
      // exp over whole packets (the bins padded to a multiple of eight): a value's exp is the
      // packet one whichever bins share its worker, not a scalar tail's in one split and a
      // packet's in another.
      padded.head(nb) = ConstArrayMap(x, nb) - max;
      e = padded.exp();
      for (Eigen::Index j = 0; j < nb; ++j) {
        const float ej = x[j] > kLogZero && ex_u[j] >= kSmallestNormal ? ex_u[j] : 0.0f;
        s[j] += ej;
        sx[j] += ej * x[j];  // x > kLogZero where ej > 0
      }
    }
    sum += row_sum.cast<double>();
    ex += row_ex.cast<double>();
  }
};

/// The log-softmax's normalizer and the frame's entropy from every bin's sums (in bin order).
struct Softmax {
  float max = kLogZero;
  double lse = 0, entropy = 0;
};

Softmax combine(const std::vector<std::optional<BinSums>>& chunks, double log_cells) {
  Softmax s;
  for (const auto& c : chunks) s.max = std::max(s.max, c->max.maxCoeff());
  if (s.max <= kLogZero) return s;
  double sum = 0, ex = 0;
  for (const auto& chunk : chunks) {
    const BinSums& c = *chunk;
    for (Eigen::Index j = 0; j < c.max.size(); ++j) {
      if (c.max[j] <= kLogZero) continue;
      const double scale = std::exp(double{c.max[j]} - s.max);
      sum += c.sum[j] * scale;
      ex += c.ex[j] * scale;
    }
  }
  s.lse = s.max + std::log(sum);
  s.entropy = std::clamp((s.lse - ex / sum) / log_cells, 0.0, 1.0);
  return s;
}

/// Writes row v of bins j0 .. j0 + nb (`row`, [u][b], nb bins a cell) into heading-major
/// `log_prob` as x - lse (values at or below kLogZero, -inf among them, as kLogZero): the portable
/// version, in tiles that keep both sides in the first-level cache.
void write_cells(const float* row, int nb, int v, int j0, int height, int width, float lse, float* log_prob) {
  constexpr int kTileBins = 8, kTileCells = 32;
  const std::size_t slice = static_cast<std::size_t>(height) * width;
  for (int tb = 0; tb < nb; tb += kTileBins) {
    const int tb1 = std::min(nb, tb + kTileBins);
    for (int tu = 0; tu < width; tu += kTileCells) {
      const int tu1 = std::min(width, tu + kTileCells);
      for (int b = tb; b < tb1; ++b) {
        float* dst = log_prob + static_cast<std::size_t>(j0 + b) * slice + static_cast<std::size_t>(v) * width;
        const float* src = row + b;
        for (int u = tu; u < tu1; ++u) {
          const float x = src[static_cast<std::size_t>(u) * static_cast<std::size_t>(nb)];
          dst[u] = x > kLogZero ? x - lse : kLogZero;
        }
      }
    }
  }
}

/// Writes row v of bins j0 .. j1 (`row`, [u][j - j0], as the filter takes them) into heading-major
/// `log_prob` as x - lse (values at or below kLogZero as kLogZero): with the AVX2 loops where they
/// apply, portable elsewhere; both write the same values.
void write_row(const float* row, int v, int j0, int j1, int height, int width, float lse, float* log_prob) {
  const std::size_t slice = static_cast<std::size_t>(height) * width;
  if (detail::intake_simd_available() && (j1 - j0) % 8 == 0 && width % 16 == 0) {
    const detail::IntakeSource source{row, VolumeType::float32, 1, width, static_cast<std::size_t>(j1 - j0)};
    (void)detail::intake_write_row_simd(
        source, 0, 0, j1 - j0, 1.0f, lse,
        log_prob + static_cast<std::size_t>(j0) * slice + static_cast<std::size_t>(v) * width, slice);
    return;
  }
  write_cells(row, j1 - j0, v, j0, height, width, lse, log_prob);
}

/// The first cell of heading-major `log_prob` (bins j0 .. j1, row v) holding `top`, or `none`.
std::size_t find_in_row(const float* log_prob, int v, int j0, int j1, int height, int width, float top,
                        std::size_t none) {
  const std::size_t slice = static_cast<std::size_t>(height) * width;
  for (int j = j0; j < j1; ++j) {
    const std::size_t begin = static_cast<std::size_t>(j) * slice + static_cast<std::size_t>(v) * width;
    const float* at = std::find(log_prob + begin, log_prob + begin + width, top);
    if (at != log_prob + begin + width) return static_cast<std::size_t>(at - log_prob);
  }
  return none;
}

/// The volume as the AVX2 loops read it.
detail::IntakeSource source_of(const FrameVolume& volume) {
  return {volume.data, volume.type, volume.height, volume.width, static_cast<std::size_t>(volume.bins)};
}

/// What a volume is told whose values leave float's range once raised to its power.
constexpr const char* kOutOfRange = ": a log-probability leaves float's range when raised to the volume's power";

/// Names the first bad cell of a volume (by its index in the file's (H, W, N) order).
[[noreturn]] void throw_bad_cell(const FrameVolume& volume, const std::string& where) {
  constexpr float kInf = std::numeric_limits<float>::infinity();
  const bool is_prob = volume.values == VolumeValues::prob;
  const std::size_t cells =
      static_cast<std::size_t>(volume.height) * static_cast<std::size_t>(volume.width) * volume.bins;
  for (std::size_t i = 0; i < cells; ++i) {
    const float raw = volume.type == VolumeType::float32
                          ? static_cast<const float*>(volume.data)[i]
                          : half_to_float(static_cast<const std::uint16_t*>(volume.data)[i]);
    std::string what;
    if (std::isnan(raw)) what = "NaN";
    if (raw == kInf) what = is_prob ? "probability +inf" : "log-probability +inf";
    if (is_prob && raw < 0) what = "probability " + std::to_string(raw) + " < 0";
    if (!what.empty()) throw IntakeError(where + ": " + what + " at cell " + std::to_string(i));
  }
  // The values are finite, but one raised to the volume's power left float's range (the SIMD sums
  // see that; a log-probability of 1e38 is no backbone's).
  throw IntakeError(where + kOutOfRange);
}

/// The first pass: each worker's bins checked (throws IntakeError naming the first bad cell) and
/// summed; the log-softmax's normalizer and the entropy of the whole volume raised to `power`.
Softmax sum_pass(const FrameVolume& volume, float power, int chunks, double log_cells, const std::string& where) {
  std::vector<std::optional<BinSums>> chunk_sums(static_cast<std::size_t>(chunks));
  std::vector<char> chunk_bad(static_cast<std::size_t>(chunks), 0);
  const bool simd = detail::intake_simd_available() && volume.values == VolumeValues::log_prob;
  core::parallel_chunks(volume.bins, chunks, [&](int j0, int j1, int t) {
    BinSums& sums = chunk_sums[static_cast<std::size_t>(t)].emplace(j1 - j0);
    if (simd) {
      if (!detail::intake_sums_simd(source_of(volume), j0, j1, power, sums.max.data(), sums.sum.data(),
                                    sums.ex.data())) {
        chunk_bad[static_cast<std::size_t>(t)] = 1;
      }
      return;
    }
    AlignedVector<float> row(static_cast<std::size_t>(volume.width) * static_cast<std::size_t>(j1 - j0));
    for (int v = 0; v < volume.height; ++v) {
      if (read_row(volume, v, j0, j1, power, row.data())) {
        chunk_bad[static_cast<std::size_t>(t)] = 1;
        return;
      }
      sums.add_row(row.data(), volume.width);
    }
  });
  if (std::find(chunk_bad.begin(), chunk_bad.end(), 1) != chunk_bad.end()) throw_bad_cell(volume, where);
  return combine(chunk_sums, log_cells);
}

/// The second pass: the volume raised to `power` written heading-major into `log_prob`, shifted by
/// -shift. Returns the first cell (heading-major) holding `top`, the largest value shifted as the
/// write shifts it (log_prob's size if none does).
std::size_t write_pass(const FrameVolume& volume, float power, int chunks, float shift, float top, float* log_prob) {
  const int H = volume.height, W = volume.width;
  const std::size_t slice = static_cast<std::size_t>(H) * static_cast<std::size_t>(W);
  const std::size_t cells = slice * static_cast<std::size_t>(volume.bins);
  const bool is_prob = volume.values == VolumeValues::prob;
  std::vector<std::size_t> chunk_first(static_cast<std::size_t>(chunks), cells);
  core::parallel_chunks(volume.bins, chunks, [&](int j0, int j1, int t) {
    const std::size_t len = static_cast<std::size_t>(W) * static_cast<std::size_t>(j1 - j0);
    const bool direct = detail::intake_simd_available() && !is_prob && (j1 - j0) % 8 == 0 && W % 16 == 0;
    AlignedVector<float> row(direct ? 0 : len);
    std::size_t& first = chunk_first[static_cast<std::size_t>(t)];
    for (int v = 0; v < H; ++v) {
      float row_max = kLogZero;
      if (direct) {  // converted, raised and written in registers
        row_max = detail::intake_write_row_simd(
            source_of(volume), v, j0, j1, power, shift,
            log_prob + static_cast<std::size_t>(j0) * slice + static_cast<std::size_t>(v) * static_cast<std::size_t>(W),
            slice);
      } else {
        // Log-probabilities at power 1 go in as converted (the write takes the zeros); otherwise
        // the values are made as the first pass made them.
        convert_row(volume, v, j0, j1, row.data());
        if (is_prob || power != 1.0f) (void)to_log_prob(row.data(), len, is_prob, power, /*check=*/false);
        write_row(row.data(), v, j0, j1, H, W, shift, log_prob);
        row_max = ConstArrayMap(row.data(), static_cast<Eigen::Index>(len)).maxCoeff();
      }
      // Rounding is monotonic: only a row whose largest value lands on `top` can hold it, and a
      // cell of a later row comes first only in a bin before the one found.
      const int last_bin = first < cells ? std::min(j1, static_cast<int>(first / slice)) : j1;
      if (row_max > kLogZero && row_max - shift == top && last_bin > j0) {
        first = std::min(first, find_in_row(log_prob, v, j0, last_bin, H, W, top, cells));
      }
    }
  });
  return *std::min_element(chunk_first.begin(), chunk_first.end());
}

}  // namespace

int intake_vector_lanes() { return detail::intake_lanes(); }

int limit_intake_vector_lanes(int lanes) {
  if (lanes != 1 && lanes != 8 && lanes != 16) {
    throw IntakeError("limit_intake_vector_lanes: 16, 8 or 1 lanes, not " + std::to_string(lanes),
                      ErrorCategory::usage);
  }
  return detail::cap_intake_lanes(lanes);
}

PreparedFrame prepare_frame(const FrameVolume& volume, int window_headings, int threads, double power) {
  std::ostringstream where;
  where << "volume of shape (" << volume.height << ", " << volume.width << ", " << volume.bins << ")";
  if (volume.data == nullptr || volume.height <= 0 || volume.width <= 0 || volume.bins <= 0) {
    throw IntakeError(where.str() + ": empty volume");
  }
  if (window_headings % volume.bins != 0 && volume.bins % window_headings != 0) {
    throw IntakeError(where.str() + ": " + std::to_string(volume.bins) +
                      " heading bins neither divide nor are a multiple of the filter's " +
                      std::to_string(window_headings));
  }
  if (!(volume.cell_m > 0)) throw IntakeError(where.str() + ": cell size must be > 0");
  if (!(power > 0) || !std::isfinite(power)) {
    throw IntakeError("prepare_frame: the power must be finite and > 0, not " + std::to_string(power),
                      ErrorCategory::usage);
  }
  PreparedFrame f;
  f.height = volume.height;
  f.width = volume.width;
  f.bins = volume.bins;
  f.cell_m = volume.cell_m;
  const std::size_t slice = static_cast<std::size_t>(volume.height) * static_cast<std::size_t>(volume.width);
  const std::size_t cells = slice * static_cast<std::size_t>(volume.bins);
  f.log_cells = std::log(static_cast<double>(cells));
  f.log_prob.resize(cells);
  // Two passes over the volume as given, each a row of cells at a time in a worker's chunk of
  // bins (a row's values stay in cache between the steps of a pass): the first checks the values
  // and sums the log-softmax (an online softmax); the second converts them again and writes them
  // heading-major, shifted. Reading float16 twice costs less than writing float32 twice.
  const int chunks = std::max(1, std::min(threads, volume.bins));
  const auto k = static_cast<float>(power);
  const Softmax softmax = sum_pass(volume, k, chunks, f.log_cells, where.str());
  if (!std::isfinite(softmax.lse)) throw IntakeError(where.str() + kOutOfRange);  // the portable sums'
  if (softmax.max <= kLogZero) throw IntakeError(where.str() + ": no probability mass (every cell is zero)");
  f.entropy = softmax.entropy;
  const auto shift = static_cast<float>(softmax.lse);
  f.max_log_prob = softmax.max - shift;  // the argmax's value, computed as write_row computes it
  std::size_t best = write_pass(volume, k, chunks, shift, f.max_log_prob, f.log_prob.data());
  if (best >= cells) {  // cannot happen (the largest value lands on top); the first largest value then
    best = static_cast<std::size_t>(std::max_element(f.log_prob.begin(), f.log_prob.end()) - f.log_prob.begin());
    f.max_log_prob = f.log_prob[best];
  }
  // The argmax, first in heading-major order.
  f.argmax_bin = static_cast<int>(best / slice);
  f.argmax_v = static_cast<int>(best % slice / static_cast<std::size_t>(f.width));
  f.argmax_u = static_cast<int>(best % static_cast<std::size_t>(f.width));
  return f;
}

void temper_frame_in_place(PreparedFrame& frame, double power, int threads) {
  if (!(power > 0) || !std::isfinite(power)) {
    throw IntakeError("temper_frame: the power must be finite and > 0, not " + std::to_string(power),
                      ErrorCategory::usage);
  }
  if (power == 1.0) return;
  ArrayMap x(frame.log_prob.data(), static_cast<Eigen::Index>(frame.log_prob.size()));
  // Zero cells stay zero; the peak's value is log p* scaled, and the log-softmax shifts it back.
  x = (x > kLogZero).select(x * static_cast<float>(power), kLogZero);
  const float max = x.maxCoeff();
  normalize(frame, max, std::max(1, std::min(threads, frame.bins)));
}

void normalize_frame(PreparedFrame& frame, int threads) {
  if (frame.log_prob.empty()) throw IntakeError("normalize_frame: the frame has no cells");
  ConstArrayMap x(frame.log_prob.data(), static_cast<Eigen::Index>(frame.log_prob.size()));
  normalize(frame, x.maxCoeff(), std::max(1, std::min(threads, frame.bins)));
}

void summarize_frame(PreparedFrame& frame, int threads) {
  if (frame.log_prob.empty()) throw IntakeError("summarize_frame: the frame has no cells");
  ConstArrayMap x(frame.log_prob.data(), static_cast<Eigen::Index>(frame.log_prob.size()));
  normalize(frame, x.maxCoeff(), std::max(1, std::min(threads, frame.bins)), /*shift=*/false);
}

float powered_peak_log_prob(const PreparedFrame& frame, double power, int threads) {
  // -log sum exp(k (x - x_max)): the peak of p^k / sum p^k. Sums per bin, added in bin order (the
  // same for any number of threads).
  const std::size_t slice = static_cast<std::size_t>(frame.width) * frame.height;
  std::vector<double> sums(static_cast<std::size_t>(frame.bins));
  core::parallel_chunks(frame.bins, std::max(1, std::min(threads, frame.bins)), [&](int j0, int j1, int) {
    std::vector<float> e(slice);
    for (int j = j0; j < j1; ++j) {
      exp_or_zero(frame.log_prob.data() + static_cast<std::size_t>(j) * slice, slice, static_cast<float>(power),
                  frame.max_log_prob, e.data());
      double sum = 0;
      for (const float x : e) sum += x;
      sums[static_cast<std::size_t>(j)] = sum;
    }
  });
  double total = 0;
  for (const double x : sums) total += x;
  return static_cast<float>(-std::log(total));
}

PreparedFrame temper_frame(PreparedFrame frame, double power, int threads) {
  temper_frame_in_place(frame, power, threads);
  return frame;
}

}  // namespace seqloc::intake
