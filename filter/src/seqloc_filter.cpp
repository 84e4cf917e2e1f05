#include "seqloc/filter/seqloc_filter.hpp"

#include <algorithm>
#include <cmath>
#include <sstream>
#include <string>

#include <Eigen/Core>

#if defined(__AVX2__)
#include <immintrin.h>
#endif

#include "internal.hpp"
#include "seqloc/core/angles.hpp"
#include "seqloc/core/thread_pool.hpp"
#include "seqloc/core/units.hpp"
#include "seqloc/filter/calibration_evidence.hpp"
#include "seqloc/filter/power_bank.hpp"

namespace seqloc::filter {
namespace {

using core::kCellM;
using core::kDegToRad;

using detail::ArrayMap;
using detail::ConstArrayMap;

}  // namespace

using detail::displacement_cells;

namespace {

// The CPU belief's position masses for StepDecisions::refine.
PositionMasses masses_of(const BeliefVolume& belief) {
  return [&belief](int u0, int v0, int u1, int v1, std::span<double> out) {
    std::size_t i = 0;
    for (int v = v0; v <= v1; ++v) {
      for (int u = u0; u <= u1; ++u) out[i++] = belief.position_mass(u, v);
    }
  };
}

}  // namespace

Pose peak_anchored_position(const BeliefVolume& belief, int u_star, int v_star, int radius) {
  FilterConfig pas_alone;
  pas_alone.headings = belief.headings();
  pas_alone.pas = true;
  pas_alone.pas_radius = radius;
  pas_alone.subbin_heading = false;
  const Pose p =
      StepDecisions(pas_alone).refine(u_star, v_star, 0, belief.width(), belief.height(), masses_of(belief), nullptr);
  return {p.u, p.v, 0};
}

// ---------------------------------------------------------------------------------------------
// The filter

struct SeqLocFilter::Impl {
  BeliefVolume scratch;           // the other buffer of predict
  AlignedVector<float> tempered;  // the frame's q^w / max, heading-major
  std::optional<PowerBank> bank;  // self-calibration's judge when FilterConfig::self_calibration_bank
  // Self-calibration's view of the predicted belief: each slice summed over 2 x 2 cells as the
  // update reads it, then `pooling` slices into one coarse bin (detail::pool_heading, as the bin
  // is judged).
  int pooling = 1;              // window bins per coarse bin
  AlignedVector<float> pooled;  // [bin][v / 2][u / 2], the bins pooled_bin() names
  PooledBelief pooled_view;     // of `pooled`
  // evidence()'s: the workers' frame cells merged, the judge's scratch and the evidence, their bins
  // reused from frame to frame.
  DepthHistogram frame_cells{DepthHistogram::kCount};
  JudgeScratch judge;
  CalibrationEvidence evidence;
  struct Worker {
    std::vector<float> sample, blend, blend_rows;
    DepthHistogram frame_cells{DepthHistogram::kCount};  // self-calibration's evidence, this worker's share
  };
  std::vector<Worker> workers;

  explicit Impl(const FilterConfig& c)
      : scratch(c.width, c.height, c.headings), workers(static_cast<std::size_t>(c.threads)) {
    for (auto& w : workers) w.sample.resize(static_cast<std::size_t>(c.width) * c.height);
    if (c.self_calibrate && c.self_calibration_bank) bank.emplace(c);
    if (c.self_calibrate && !c.self_calibration_bank) {
      pooling = detail::calibration_bins(c.headings);
      pooled.resize(pooled_belief_for(c, nullptr).slice_cells() * static_cast<std::size_t>(c.headings));
      pooled_view = pooled_belief_for(c, pooled.data());
    }
  }

  // Self-calibration's reading of the given frame: its cells binned by depth below the peak (each
  // worker's share in its frame_cells; the bins the coarse belief is judged at, each counting for
  // the bins around it) and, for power k != 1, the peak and entropy of q = p^k / Z: with
  // r = log p - log p_max, log q_max = -log Z, Z = sum e^{k r} and H = log Z - k sum(e^{k r} r) / Z.
  // The sums are kept per heading bin and added in bin order, so that they do not depend on the
  // number of threads. scan_frame() reads the frame for it alone; the update's temper() reads each
  // bin right after tempering it, while it is in cache.
  struct Scan {
    static constexpr std::size_t kBlock = 4096;
    explicit Scan(const PreparedFrame& frame, double power)
        : f(frame),
          k(static_cast<float>(power)),
          raised(power != 1.0),
          stride(detail::calibration_bins(frame.bins)),
          bin_z(static_cast<std::size_t>(frame.bins)),
          bin_zr(static_cast<std::size_t>(frame.bins)) {}
    const PreparedFrame& f;
    float k;
    bool raised;
    int stride;
    std::vector<double> bin_z, bin_zr;
  };

  // Bin j of a Scan. `raised_given`, when given, already holds e^{k r} for every cell of the frame
  // (the update's tempered frame where ETU's weight is 1): no exp then.
  void scan_bin(Scan& scan, int j, int worker, const float* raised_given) {
    const PreparedFrame& f = scan.f;
    const bool binned = !bank.has_value() && j % scan.stride == 0;
    if (!binned && !scan.raised) return;  // nothing to read in this bin (z, zr stay 0, unused)
    const std::size_t slice = static_cast<std::size_t>(f.width) * f.height;
    const auto count = static_cast<float>(scan.stride);
    // Aligned blocks: sums that do not depend on the heap.
    Eigen::ArrayXf r(Scan::kBlock), one(Scan::kBlock), e(Scan::kBlock);
    auto& cells = workers[static_cast<std::size_t>(worker)].frame_cells;
    double z = 0, zr = 0;
    for (std::size_t start = 0; start < slice; start += Scan::kBlock) {
      const std::size_t len = std::min(Scan::kBlock, slice - start);
      const float* x = f.log_prob.data() + static_cast<std::size_t>(j) * slice + start;
      for (Eigen::Index i = 0; i < static_cast<Eigen::Index>(len); ++i) {  // vectorizes
        r[i] = std::max(x[i], kLogZero) - f.max_log_prob;
        one[i] = x[i] > kLogZero ? count : 0.0f;
      }
      if (binned) cells.add_each({r.data(), len}, {one.data(), len});
      if (scan.raised) {
        const float* eb_data = e.data();
        if (raised_given != nullptr) {
          eb_data = raised_given + static_cast<std::size_t>(j) * slice + start;
        } else {
          detail::exp_or_zero(x, len, scan.k, f.max_log_prob, e.data());
        }
        ConstArrayMap eb(eb_data, static_cast<Eigen::Index>(len));
        z += eb.sum();
        zr += (eb * ConstArrayMap(r.data(), static_cast<Eigen::Index>(len))).sum();  // 0 * kLogZero at a zero cell
      }
    }
    scan.bin_z[static_cast<std::size_t>(j)] = z;
    scan.bin_zr[static_cast<std::size_t>(j)] = zr;
  }

  static FrameShape scanned_shape(const Scan& scan, double power) {
    const PreparedFrame& f = scan.f;
    if (!scan.raised) return {f.max_log_prob, f.entropy};
    double z = 0, zr = 0;
    for (int j = 0; j < f.bins; ++j) {
      z += scan.bin_z[static_cast<std::size_t>(j)];
      zr += scan.bin_zr[static_cast<std::size_t>(j)];
    }
    const double log_z = std::log(z);  // z >= 1: the peak's own cell counts e^0
    return {static_cast<float>(-log_z), std::clamp((log_z - power * zr / z) / f.log_cells, 0.0, 1.0)};
  }

  FrameShape scan_frame(const PreparedFrame& f, double power, int threads) {
    Scan scan(f, power);
    core::parallel_chunks(f.bins, threads, [&](int j0, int j1, int t) {
      for (int j = j0; j < j1; ++j) scan_bin(scan, j, t, nullptr);
    });
    return scanned_shape(scan, power);
  }
};

namespace {

// o[i] = r[2 i] + r[2 i + 1] for i < pairs.
void add_pairs(const float* __restrict r, int pairs, float* __restrict o) {
  int i = 0;
#if defined(__AVX2__)
  for (; i + 8 <= pairs; i += 8) {
    // hadd pairs within 128-bit lanes: (r0+r1, r2+r3, r8+r9, r10+r11 | r4+r5, r6+r7, r12+r13, r14+r15);
    // the 64-bit permute puts them in order.
    const __m256 sums = _mm256_hadd_ps(_mm256_loadu_ps(r + 2 * i), _mm256_loadu_ps(r + 2 * i + 8));
    _mm256_storeu_ps(o + i, _mm256_castpd_ps(_mm256_permute4x64_pd(_mm256_castps_pd(sums), 0xD8)));
  }
#endif
  for (; i < pairs; ++i) o[i] = r[2 * i] + r[2 * i + 1];
}

// The update of n cells of the belief: b <- b * sample (or sample alone without the prior), then
// times the GPS term where given.
void update_cells(float* __restrict b, const float* __restrict sample, const float* __restrict gps, bool with_prior,
                  std::size_t n) {
  if (with_prior) {
    for (std::size_t i = 0; i < n; ++i) b[i] *= sample[i];
  } else {
    std::copy(sample, sample + n, b);
  }
  if (gps != nullptr) {
    for (std::size_t i = 0; i < n; ++i) b[i] *= gps[i];
  }
}

// update_cells over one slice and, for self-calibration, the predicted slice summed over 2 x 2
// cells into `pooled` ((width + 1) / 2 wide; the last row or column alone where the size is odd)
// as math::pool_2x2 adds them: row pair by row pair, so that the belief is read from memory once.
void update_pooling(float* slice, const float* sample, const float* gps, bool with_prior, int width, int height,
                    std::vector<float>& row_pair, float* pooled) {
  const int cw = (width + 1) / 2, pairs = width / 2;
  row_pair.resize(static_cast<std::size_t>(width));
  float* __restrict r = row_pair.data();
  for (int cv = 0; cv < (height + 1) / 2; ++cv) {
    const int rows = 2 * cv + 1 < height ? 2 : 1;
    const std::size_t at = static_cast<std::size_t>(2 * cv) * width;
    float* __restrict a = slice + at;
    if (rows == 2) {
      const float* __restrict b = a + width;
      for (int u = 0; u < width; ++u) r[u] = a[u] + b[u];
    } else {
      std::copy(a, a + width, r);
    }
    float* o = pooled + static_cast<std::size_t>(cv) * cw;
    add_pairs(r, pairs, o);
    if (cw > pairs) o[pairs] = r[width - 1];
    update_cells(a, sample + at, gps != nullptr ? gps + at : nullptr, with_prior,
                 static_cast<std::size_t>(rows) * width);
  }
}

}  // namespace

SeqLocFilter::SeqLocFilter(const FilterConfig& config)
    : config_((config.validate(), config)),
      belief_(config.width, config.height, config.headings),
      impl_(std::make_unique<Impl>(config)),
      decisions_(config) {}

SeqLocFilter::~SeqLocFilter() = default;

void SeqLocFilter::reset_uniform() {
  belief_.set_uniform();
  cached_min_.reset();
  if (impl_->bank) impl_->bank->reset();
  decisions_.reset();
}

void SeqLocFilter::reset_gaussian(double u, double v, double sigma_m) {
  belief_.set_gaussian(u, v, sigma_m / kCellM);
  cached_min_.reset();
  if (impl_->bank) impl_->bank->reset(belief_);
  decisions_.reset();
}

const PowerBank* SeqLocFilter::power_bank() const { return impl_->bank ? &*impl_->bank : nullptr; }

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
  decisions_.rebase(last_estimate);
  if (impl_->bank) impl_->bank->rebase(belief_);
}

void SeqLocFilter::recentre(int du, int dv) {
  if (du != 0 || dv != 0) {
    // The entering cells take the window's minimum, so the minimum stays what it was.
    const float fill = cached_min_ ? *cached_min_ : belief_.min_value();
    belief_.recentre(du, dv, fill, config_.threads);
    cached_min_ = fill;
  }
  decisions_.recentre(du, dv);
  if (impl_->bank) impl_->bank->recentre(du, dv);
}

void SeqLocFilter::predict(const Odometry& odometry) {
  const int W = config_.width, H = config_.height, R = config_.headings;
  // The window's minimum: kept from the end of the last step unless the belief was handed out
  // for writing since.
  const float fill = cached_min_ ? *cached_min_ : belief_.min_value();
  detail::warp_volume(belief_, impl_->scratch, odometry, fill, config_.threads);
  cached_min_.reset();
  std::swap(belief_, impl_->scratch);
  if (impl_->bank) impl_->bank->predict(odometry);

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
    auto idx = [&](int u, int v, int k) {
      return static_cast<std::size_t>(k) * n + static_cast<std::size_t>(v) * W + u;
    };
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

void SeqLocFilter::predict(const Odometry& odometry, BeliefVolume& previous) {
  if (previous.width() != config_.width || previous.height() != config_.height ||
      previous.headings() != config_.headings) {
    throw FilterError("predict: the belief to hand over is not of the window's shape", ErrorCategory::internal);
  }
  predict(odometry);
  std::swap(previous, impl_->scratch);  // the motion's source, until the next motion overwrites it
}

void SeqLocFilter::load(const PreparedFrame& /*frame*/, bool estimating) {
  // The frame stays where the caller holds it; scan_frame() bins its cells for the estimator.
  if (estimating) {
    for (auto& worker : impl_->workers) worker.frame_cells.clear();
  }
}

FrameShape SeqLocFilter::powered_shape(const PreparedFrame& frame, double power) {
  return impl_->scan_frame(frame, power, config_.threads);
}

void SeqLocFilter::raise(float ratio) {
  std::vector<double> sums(static_cast<std::size_t>(config_.headings));
  const auto n = static_cast<Eigen::Index>(belief_.slice_cells());
  core::parallel_chunks(config_.headings, config_.threads, [&](int k0, int k1, int) {
    for (int k = k0; k < k1; ++k) {
      ArrayMap b(belief_.slice(k), n);
      b = b.pow(ratio);
      sums[static_cast<std::size_t>(k)] = static_cast<double>(b.sum());
    }
  });
  double total = 0;
  for (const double x : sums) total += x;
  if (!(total > 0) || !std::isfinite(total)) return;
  const auto scale = static_cast<float>(1 / total);
  core::parallel_chunks(config_.headings, config_.threads, [&](int k0, int k1, int) {
    for (int k = k0; k < k1; ++k) ArrayMap(belief_.slice(k), n) *= scale;
  });
  cached_min_.reset();
}

std::optional<FrameShape> SeqLocFilter::temper(const PreparedFrame& frame, float exponent,
                                               std::optional<double> shape_power) {
  impl_->tempered.resize(frame.log_prob.size());
  // With `shape_power`, self-calibration's scan reads each bin right after it is tempered; where
  // ETU's weight is 1 the tempered frame is the powered frame's numerator e^{kappa r} itself.
  std::optional<Impl::Scan> scan;
  if (shape_power) scan.emplace(frame, *shape_power);
  const float* powered = shape_power && exponent == static_cast<float>(*shape_power) ? impl_->tempered.data() : nullptr;
  core::parallel_chunks(frame.bins, config_.threads, [&](int j0, int j1, int t) {
    const std::size_t slice = static_cast<std::size_t>(frame.width) * frame.height;
    for (int j = j0; j < j1; ++j) {  // bin by bin: the same cuts for any number of threads
      const std::size_t begin = static_cast<std::size_t>(j) * slice;
      detail::exp_or_zero(frame.log_prob.data() + begin, slice, exponent, frame.max_log_prob,
                          impl_->tempered.data() + begin);
      if (scan) impl_->scan_bin(*scan, j, t, powered);
    }
  });
  if (!scan) return std::nullopt;
  return Impl::scanned_shape(*scan, *shape_power);
}

double SeqLocFilter::multiply_in(const PreparedFrame& frame, const CropPose& crop, float outside,
                                 std::span<const float> gps_term, bool with_prior, bool pool) {
  const int W = config_.width, H = config_.height, R = config_.headings;
  const auto N = static_cast<Eigen::Index>(belief_.slice_cells());
  // Update: b_hat + w log p, i.e. prob *= p^w, slice by slice with each slice's sum; the predicted
  // belief pooled for self-calibration, each slice while it is at hand.
  std::vector<double> slice_sum(static_cast<std::size_t>(R));
  core::parallel_chunks(R, config_.threads, [&](int k0, int k1, int t) {
    auto& worker = impl_->workers[static_cast<std::size_t>(t)];
    for (int k = k0; k < k1; ++k) {
      detail::sample_slice(impl_->tempered.data(), frame.bins, frame.height, frame.width, frame.cell_m, crop,
                           belief_.bin_heading_deg(k), W, H, outside, worker.blend, worker.sample.data());
      const float* gps = gps_term.empty() ? nullptr : gps_term.data();
      if (pool && detail::pooled_bin(k, impl_->pooling)) {
        update_pooling(belief_.slice(k), worker.sample.data(), gps, with_prior, W, H, worker.blend_rows,
                       impl_->pooled.data() + static_cast<std::size_t>(k) * impl_->pooled_view.slice_cells());
      } else {
        update_cells(belief_.slice(k), worker.sample.data(), gps, with_prior, static_cast<std::size_t>(N));
      }
      slice_sum[static_cast<std::size_t>(k)] = static_cast<double>(ArrayMap(belief_.slice(k), N).sum());
    }
  });
  double total = 0;
  for (double x : slice_sum) total += x;
  return total;
}

const CalibrationEvidence& SeqLocFilter::evidence(const PreparedFrame& frame, const CropPose& crop) {
  // The predicted belief on the coarse grid (1 m cells, a few heading bins in each), judged by
  // the frame at each power: a sixteenth of the cells, and the same estimate to within the
  // frame-to-frame noise of the estimate itself (docs/filter.md, "Self-calibration").
  DepthHistogram& frame_cells = impl_->frame_cells;
  frame_cells.clear();
  for (const auto& worker : impl_->workers) frame_cells.merge(worker.frame_cells);
  coarse_evidence(impl_->pooled_view, frame, crop, config_, frame_cells, impl_->judge, impl_->evidence);
  return impl_->evidence;
}

BeliefPeak SeqLocFilter::normalize(double total, std::span<const float> road_distance_m) {
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
  const auto cell = static_cast<int>(
      std::find(star_slice, star_slice + n, best_value[static_cast<std::size_t>(k_star)]) - star_slice);
  return {cell % W, cell / W, k_star, best_value[static_cast<std::size_t>(k_star)]};
}

PositionMasses SeqLocFilter::position_masses() { return masses_of(belief_); }

CellValue SeqLocFilter::cell_value() {
  return [this](int u, int v, int k) { return static_cast<double>(belief_.prob(u, v, k)); };
}

std::optional<double> SeqLocFilter::bank_power() const {
  return impl_->bank ? std::optional<double>(impl_->bank->power()) : std::nullopt;
}

void SeqLocFilter::bank_judge(const PreparedFrame& frame, const CropPose& crop, double etu_weight) {
  impl_->bank->update(frame, crop, etu_weight);
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
