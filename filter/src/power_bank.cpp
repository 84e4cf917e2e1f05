// Self-calibration's bank of coarse filters (power_bank.hpp).

#include "seqloc/filter/power_bank.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

#include <Eigen/Core>

#include "internal.hpp"
#include "seqloc/core/thread_pool.hpp"

namespace seqloc::filter {
namespace {

constexpr float kOutside = 1.0f;  // sample_slice's fill: no log-probability is positive

// floor(a / 2) for any sign.
int floor_half(int a) { return a >= 0 ? a / 2 : -((1 - a) / 2); }

}  // namespace

int PowerBank::heading_pooling(int headings) {
  for (int p = 8; p > 1; p /= 2)
    if (headings % p == 0 && headings / p >= 16) return p;
  return 1;
}

PowerBank::PowerBank(const FilterConfig& config)
    : config_(config),
      pooling_(heading_pooling(config.headings)),
      scratch_((config.width + 1) / 2, (config.height + 1) / 2, config.headings / pooling_) {
  for (int o = kMinOctave; o <= kMaxOctave; ++o) {
    powers_.push_back(std::exp2(o));
    const double z = o / config.self_calibration_prior_octaves;
    log_prior_.push_back(-0.5 * z * z);
    members_.emplace_back(scratch_.width(), scratch_.height(), scratch_.headings());
  }
  sampled_.resize(scratch_.size());
  reset();
}

void PowerBank::reset() {
  for (auto& m : members_) m.set_uniform();
  scores_ = log_prior_;
  power_ = 1;
  frames_ = 0;
  origin_u_ = origin_v_ = 0;
}

void PowerBank::reset(const BeliefVolume& belief) {
  reset();
  rebase(belief);
}

void PowerBank::rebase(const BeliefVolume& belief) {
  // Pooled: each coarse cell the sum of its 2 x 2 window cells, each coarse bin of the window bins
  // around its heading (those half a coarse bin away, shared with the neighbour, at half weight).
  origin_u_ = origin_v_ = 0;
  BeliefVolume& out = members_.front();
  const int W = belief.width(), H = belief.height(), R = belief.headings();
  const int cw = out.width(), p = pooling_, half = p / 2;
  core::parallel_chunks(out.headings(), config_.threads, [&](int j0, int j1, int) {
    for (int j = j0; j < j1; ++j) {
      float* o = out.slice(j);
      std::fill(o, o + out.slice_cells(), 0.0f);
      for (int d = (p == 1 ? 0 : -half); d <= (p == 1 ? 0 : half); ++d) {
        const float weight = p > 1 && (d == -half || d == half) ? 0.5f : 1.0f;
        const float* in = belief.slice(((j * p + d) % R + R) % R);
        for (int v = 0; v < H; ++v)
          for (int u = 0; u < W; ++u)
            o[static_cast<std::size_t>(v / 2) * cw + u / 2] += weight * in[static_cast<std::size_t>(v) * W + u];
      }
    }
  });
  const double total = out.total_probability();
  if (total > 0 && std::isfinite(total)) {
    const auto scale = static_cast<float>(1 / total);
    for (std::size_t i = 0; i < out.size(); ++i) out.data()[i] *= scale;
  } else {
    out.set_uniform();
  }
  for (std::size_t i = 1; i < members_.size(); ++i) members_[i] = members_.front();
}

void PowerBank::recentre(int du, int dv) {
  // Coarse cell X covers window cells origin + 2X and the next; after the window's move by du they
  // are origin - du + 2X: the coarse grid moves by whole coarse cells, the rest stays in origin.
  const int su = floor_half(origin_u_ - du), sv = floor_half(origin_v_ - dv);
  origin_u_ = origin_u_ - du - 2 * su;
  origin_v_ = origin_v_ - dv - 2 * sv;
  if (su == 0 && sv == 0) return;
  for (auto& m : members_) m.recentre(-su, -sv);
}

void PowerBank::predict(const Odometry& odometry) {
  // Displacements in coarse cells (1 m): the odometry at half its length moved on 0.5 m cells.
  const Odometry coarse{odometry.forward_m / 2, odometry.left_m / 2, odometry.yaw_deg};
  for (auto& m : members_) {
    detail::warp_volume(m, scratch_, coarse, m.min_value(), config_.threads);
    std::swap(m, scratch_);
  }
}

void PowerBank::pool_frame(const PreparedFrame& f) {
  // The frame's log-probabilities max-pooled to about the coarse cells: 2 x 2 cells of 0.5 m, and
  // the bins around each coarse bin's heading where the frame has more bins than the bank.
  const int coarse_bins = scratch_.headings();
  const int hp = f.bins > coarse_bins && f.bins % coarse_bins == 0 ? f.bins / coarse_bins : 1, half = hp / 2;
  const int sf = f.cell_m < 0.75 ? 2 : 1;
  pooled_bins_ = f.bins / hp;
  pooled_height_ = (f.height + sf - 1) / sf;
  pooled_width_ = (f.width + sf - 1) / sf;
  pooled_cell_m_ = f.cell_m * sf;
  const std::size_t slice = static_cast<std::size_t>(f.width) * f.height;
  const std::size_t out_slice = static_cast<std::size_t>(pooled_width_) * pooled_height_;
  pooled_.assign(out_slice * static_cast<std::size_t>(pooled_bins_), kLogZero);
  core::parallel_chunks(pooled_bins_, config_.threads, [&](int j0, int j1, int) {
    for (int j = j0; j < j1; ++j) {
      float* o = pooled_.data() + static_cast<std::size_t>(j) * out_slice;
      for (int d = (hp == 1 ? 0 : -half); d <= (hp == 1 ? 0 : half); ++d) {
        const float* in =
            f.log_prob.data() + static_cast<std::size_t>(((j * hp + d) % f.bins + f.bins) % f.bins) * slice;
        for (int v = 0; v < f.height; ++v) {
          float* row = o + static_cast<std::size_t>(v / sf) * pooled_width_;
          const float* src = in + static_cast<std::size_t>(v) * f.width;
          for (int u = 0; u < f.width; ++u) row[u / sf] = std::max(row[u / sf], std::max(src[u], kLogZero));
        }
      }
    }
  });
}

void PowerBank::sample_frame(const CropPose& crop) {
  // Coarse cell X's centre is window cell origin + 2X + 0.5.
  const CropPose at{(crop.centre_u - origin_u_ - 0.5) / 2, (crop.centre_v - origin_v_ - 0.5) / 2, crop.rotation_deg};
  const std::size_t n = scratch_.slice_cells();
  core::parallel_chunks(scratch_.headings(), config_.threads, [&](int j0, int j1, int) {
    std::vector<float> blend;
    for (int j = j0; j < j1; ++j) {
      detail::sample_slice(pooled_.data(), pooled_bins_, pooled_height_, pooled_width_, pooled_cell_m_ / 2, at,
                           scratch_.bin_heading_deg(j), scratch_.width(), scratch_.height(), kOutside, blend,
                           sampled_.data() + static_cast<std::size_t>(j) * n);
    }
  });
}

void PowerBank::update(const PreparedFrame& frame, const CropPose& crop, double etu_weight) {
  pool_frame(frame);
  sample_frame(crop);
  const int R = scratch_.headings();
  const std::size_t n = scratch_.slice_cells();
  // The crop's cells on the coarse window and the highest log-probability among them.
  std::vector<double> bin_inside(static_cast<std::size_t>(R));
  std::vector<float> bin_max(static_cast<std::size_t>(R), kLogZero);
  core::parallel_chunks(R, config_.threads, [&](int j0, int j1, int) {
    for (int j = j0; j < j1; ++j) {
      const float* s = sampled_.data() + static_cast<std::size_t>(j) * n;
      std::size_t inside = 0;
      float best = kLogZero;
      for (std::size_t i = 0; i < n; ++i) {
        if (s[i] <= 0.5f) {
          ++inside;
          best = std::max(best, s[i]);
        }
      }
      bin_inside[static_cast<std::size_t>(j)] = static_cast<double>(inside);
      bin_max[static_cast<std::size_t>(j)] = best;
    }
  });
  double inside = 0;
  for (const double x : bin_inside) inside += x;
  const float peak = *std::max_element(bin_max.begin(), bin_max.end());
  if (inside == 0 || !(peak > kLogZero)) return;  // the frame sees nothing of the window
  const double all = static_cast<double>(scratch_.size());
  const double outside_value = std::exp(-std::log(inside) - config_.outside_crop_nats);
  const double rho = config_.self_calibration_outlier_share;
  const double uniform = (1 + (all - inside) * outside_value) / all;
  pooled_.resize(scratch_.size());  // reused: the frame raised to a member's power
  std::vector<double> log_p(members_.size(), 0.0);
  for (std::size_t m = 0; m < members_.size(); ++m) {
    const double predictive = step_member(members_[m], etu_weight * powers_[m], peak, outside_value);
    log_p[m] = std::log((1 - rho) * predictive + rho * uniform);
  }
  if (std::all_of(log_p.begin(), log_p.end(), [](double x) { return std::isfinite(x); })) {
    for (std::size_t m = 0; m < members_.size(); ++m) scores_[m] += log_p[m];
    ++frames_;
    choose_power();
  }
}

double PowerBank::step_member(BeliefVolume& b, double power, float peak, double outside_value) {
  const int R = scratch_.headings();
  const std::size_t n = scratch_.slice_cells();
  const auto N = static_cast<Eigen::Index>(n);
  AlignedVector<float>& raised = pooled_;
  struct Sums {
    double z = 0, belief_in = 0, belief_out = 0, belief = 0;
  };
  std::vector<Sums> sums(static_cast<std::size_t>(R));
  const auto a = static_cast<float>(power);
  // e = exp(a (s - peak)) in the crop; the sums for Z, the predictive and the belief's total.
  core::parallel_chunks(R, config_.threads, [&](int j0, int j1, int) {
    for (int j = j0; j < j1; ++j) {
      const std::size_t at = static_cast<std::size_t>(j) * n;
      float* e = raised.data() + at;
      const float* s = sampled_.data() + at;
      detail::exp_or_zero(s, n, a, peak, e);
      const float* x = b.slice(j);
      Sums sj;
      for (std::size_t i = 0; i < n; ++i) {
        const bool in = s[i] <= 0.5f;
        if (!in) e[i] = 0.0f;
        sj.z += e[i];
        sj.belief_in += static_cast<double>(x[i]) * e[i];
        sj.belief_out += in ? 0.0 : x[i];
        sj.belief += x[i];
      }
      sums[static_cast<std::size_t>(j)] = sj;
    }
  });
  Sums s;
  for (const Sums& sj : sums) {
    s.z += sj.z;
    s.belief_in += sj.belief_in;
    s.belief_out += sj.belief_out;
    s.belief += sj.belief;
  }
  const double predictive = s.belief > 0 ? (s.belief_in / s.z + outside_value * s.belief_out) / s.belief : 0.0;
  // The update: b times L (e / Z in the crop, outside_value out of it), normalized.
  const auto out_scaled = static_cast<float>(outside_value * s.z);
  const bool alone = !(s.belief_in + outside_value * s.z * s.belief_out > 0);  // no shared support
  std::vector<double> totals(static_cast<std::size_t>(R));
  core::parallel_chunks(R, config_.threads, [&](int j0, int j1, int) {
    for (int j = j0; j < j1; ++j) {
      const std::size_t at = static_cast<std::size_t>(j) * n;
      float* __restrict x = b.slice(j);
      const float* __restrict e = raised.data() + at;
      const float* __restrict smp = sampled_.data() + at;
      for (std::size_t i = 0; i < n; ++i) {
        const float likelihood = smp[i] <= 0.5f ? e[i] : out_scaled;
        x[i] = alone ? likelihood : x[i] * likelihood;
      }
      totals[static_cast<std::size_t>(j)] = static_cast<double>(detail::ConstArrayMap(x, N).sum());
    }
  });
  double total = 0;
  for (const double t : totals) total += t;
  if (!(total > 0) || !std::isfinite(total)) {
    b.set_uniform();
    return predictive;
  }
  const auto scale = static_cast<float>(1 / total);
  core::parallel_chunks(R, config_.threads, [&](int j0, int j1, int) {
    for (int j = j0; j < j1; ++j) detail::ArrayMap(b.slice(j), N) *= scale;
  });
  return predictive;
}

void PowerBank::choose_power() {
  const auto best = static_cast<std::size_t>(std::max_element(scores_.begin(), scores_.end()) - scores_.begin());
  double octave = std::log2(powers_[best]);
  if (best > 0 && best + 1 < scores_.size()) {
    // The vertex of the parabola through the best member and its neighbours (within half an octave).
    const double a = scores_[best - 1], b = scores_[best], c = scores_[best + 1];
    const double curvature = a - 2 * b + c;
    if (curvature < 0) octave += 0.5 * (a - c) / curvature;
  }
  power_ = std::exp2(octave);
}

}  // namespace seqloc::filter
