// Self-calibration's evidence on the coarse grid (internal.hpp).

#include "seqloc/filter/calibration_evidence.hpp"

#include <algorithm>
#include <vector>

#include "internal.hpp"
#include "seqloc/core/thread_pool.hpp"

namespace seqloc::filter::detail {

void pool_heading(const PooledBelief& pooled, int j, float* out) {
  const int b = calibration_bins(pooled.headings), half = b / 2;
  const std::size_t n = pooled.slice_cells();
  std::fill(out, out + n, 0.0f);
  for (int d = -half; d <= half; ++d) {
    const int k = ((b * j + d) % pooled.headings + pooled.headings) % pooled.headings;
    if (!pooled_bin(k, b)) continue;
    const float weight = math::pooled_weight(d, b);
    const float* in = pooled.slices + static_cast<std::size_t>(k) * n;
    for (std::size_t i = 0; i < n; ++i) out[i] += weight * in[i];
  }
}

void judge_frame(const PooledBelief& pooled, const PreparedFrame& frame, double frame_cell_m, const CropPose& crop,
                 double cells_per_cell, int threads, JudgeScratch& scratch, CalibrationEvidence& evidence) {
  const int w = pooled.width, h = pooled.height, r = pooled.headings / calibration_bins(pooled.headings);
  const std::size_t n = pooled.slice_cells();
  constexpr float kOutside = 1.0f;  // no log-probability is positive
  auto& shares = scratch.shares;
  shares.resize(static_cast<std::size_t>(std::max(1, threads)));
  for (auto& s : shares) s.in_crop.clear();
  // Per bin, added in bin order: the same sums for any number of threads.
  std::vector<double> outside(static_cast<std::size_t>(r));
  std::vector<std::size_t> outside_cells(static_cast<std::size_t>(r));
  core::parallel_chunks(r, threads, [&](int k0, int k1, int t) {
    JudgeScratch::Share& s = shares[static_cast<std::size_t>(t)];
    s.sample.resize(n);
    s.depth.resize(n);
    s.mass.resize(n);
    for (int k = k0; k < k1; ++k) {
      sample_slice(frame.log_prob.data(), frame.bins, frame.height, frame.width, frame_cell_m, crop,
                   bin_heading_deg(k, r), w, h, kOutside, s.blend, s.sample.data());
      pool_heading(pooled, k, s.mass.data());
      const float* mass = s.mass.data();
      double out = 0;
      std::size_t out_cells = 0;
      for (std::size_t i = 0; i < n; ++i) {
        const float x = s.sample[i];
        const bool in = x <= 0.5f;
        out += in ? 0.0 : mass[i];
        out_cells += in ? 0 : 1;
        s.depth[i] = in ? std::max(x, kLogZero) - frame.max_log_prob : 0.0f;
        // The weight: the mass in the crop (none below 1e-12, which no sum here can see: fewer
        // cells for the histogram to bin).
        s.sample[i] = in && mass[i] >= 1e-12f ? mass[i] : 0.0f;
      }
      s.in_crop.add_each(s.depth, s.sample);
      outside[static_cast<std::size_t>(k)] = out;
      outside_cells[static_cast<std::size_t>(k)] = out_cells;
    }
  });
  for (const JudgeScratch::Share& s : shares) evidence.belief_in_crop.merge(s.in_crop);
  for (int k = 0; k < r; ++k) {
    evidence.belief_outside += outside[static_cast<std::size_t>(k)];
    evidence.outside_cells += static_cast<double>(outside_cells[static_cast<std::size_t>(k)]) * cells_per_cell;
  }
  evidence.window_cells = static_cast<double>(n) * r * cells_per_cell;
}

}  // namespace seqloc::filter::detail

namespace seqloc::filter {

PooledBelief pooled_belief_for(const FilterConfig& config, const float* slices) {
  return {slices, (config.width + 1) / 2, (config.height + 1) / 2, config.headings};
}

BeliefVolume coarse_belief_for(const FilterConfig& config) {
  const PooledBelief pooled = pooled_belief_for(config, nullptr);
  return {pooled.width, pooled.height, config.headings / detail::calibration_bins(config.headings)};
}

void add_frame_cells(const PreparedFrame& frame, DepthHistogram& cells) {
  const std::size_t slice = static_cast<std::size_t>(frame.width) * frame.height;
  const int stride = detail::calibration_bins(frame.bins);
  const auto count = static_cast<float>(stride);
  std::vector<float> r(slice), one(slice);
  for (int j = 0; j < frame.bins; j += stride) {
    const float* x = frame.log_prob.data() + static_cast<std::size_t>(j) * slice;
    for (std::size_t i = 0; i < slice; ++i) {
      r[i] = std::max(x[i], kLogZero) - frame.max_log_prob;
      one[i] = x[i] > kLogZero ? count : 0.0f;
    }
    cells.add_each(r, one);
  }
}

void coarse_evidence(const PooledBelief& pooled, const PreparedFrame& frame, const CropPose& crop,
                     const FilterConfig& config, const DepthHistogram& frame_cells, JudgeScratch& scratch,
                     CalibrationEvidence& evidence) {
  evidence.clear();
  evidence.log_outside = -frame.log_cells - config.outside_crop_nats;
  evidence.frame_cells.merge(frame_cells);
  const CropPose at{(crop.centre_u - 0.5) / 2, (crop.centre_v - 0.5) / 2, crop.rotation_deg};
  const double cells_per_cell = 4.0 * detail::calibration_bins(config.headings);
  detail::judge_frame(pooled, frame, frame.cell_m / 2, at, cells_per_cell, config.threads, scratch, evidence);
}

}  // namespace seqloc::filter
