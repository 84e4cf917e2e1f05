#include "seqloc/filter/smoother.hpp"

#include <algorithm>
#include <cmath>
#include <vector>

#include <Eigen/Core>

#include "internal.hpp"
#include "seqloc/core/angles.hpp"
#include "seqloc/core/thread_pool.hpp"

namespace seqloc::filter {
namespace {

using detail::ArrayMap;
using detail::ConstArrayMap;

// The backward filter's own configuration: the forward one's, without self-calibration's buffers
// (it is given every frame's weighting).
FilterConfig backward_config(FilterConfig config) {
  config.self_calibrate = false;
  return config;
}

}  // namespace

BackwardFilter::BackwardFilter(const FilterConfig& config) : filter_(backward_config(config)) { reset(); }

void BackwardFilter::reset() { filter_.reset_uniform(); }

void BackwardFilter::absorb(const PreparedFrame& frame, const CropPose& crop, const FrameWeighting& weighting,
                            std::span<const float> road_distance_m, const std::optional<GpsFix>& gps) {
  (void)filter_.update(frame, crop, road_distance_m, gps, weighting);
}

void BackwardFilter::step_back(const Odometry& odometry) { filter_.predict(invert(odometry)); }

namespace {

// The product gamma = alpha * beta over the window, reduced per heading slice.
struct SlicedProduct {
  std::vector<float> best;  ///< each slice's largest value
  std::vector<double> sum;  ///< each slice's sum
  bool both = true;         ///< false: the forward belief alone (beta taken as uniform)
  double total = 0;         ///< the sums added in slice order (the same for any number of threads)
};

void check_shapes(const BeliefVolume& forward, const BeliefVolume& backward, const BeliefVolume* posterior) {
  if (forward.width() != backward.width() || forward.height() != backward.height() ||
      forward.headings() != backward.headings()) {
    throw FilterError("smoothed_result: the forward and backward beliefs cover different windows",
                      ErrorCategory::internal);
  }
  if (posterior != nullptr && (posterior->width() != forward.width() || posterior->height() != forward.height() ||
                               posterior->headings() != forward.headings())) {
    throw FilterError("smoothed_result: the posterior's shape differs from the beliefs'", ErrorCategory::internal);
  }
}

// gamma's slices reduced (and written to `posterior` as they are, when given). When the two
// passes share no mass that float can represent (they placed the vehicle apart with certainty),
// the forward belief alone decides, as the filter lets a frame alone decide.
SlicedProduct reduce_product(const BeliefVolume& forward, const BeliefVolume& backward, const FilterConfig& config,
                             BeliefVolume* posterior) {
  const int R = forward.headings();
  const auto N = static_cast<Eigen::Index>(forward.slice_cells());
  SlicedProduct p;
  p.best.resize(static_cast<std::size_t>(R));
  p.sum.resize(static_cast<std::size_t>(R));
  // Each slice's product is written where it stays (the posterior, else a worker's scratch) and
  // reduced there while it is in cache.
  auto reduce = [&](bool both) {
    core::parallel_chunks(R, config.threads, [&](int k0, int k1, int) {
      Eigen::ArrayXf scratch(posterior != nullptr ? 0 : N);
      for (int k = k0; k < k1; ++k) {
        ArrayMap product(posterior != nullptr ? posterior->slice(k) : scratch.data(), N);
        if (both) {
          product = ConstArrayMap(forward.slice(k), N) * ConstArrayMap(backward.slice(k), N);
        } else {
          product = ConstArrayMap(forward.slice(k), N);
        }
        p.best[static_cast<std::size_t>(k)] = product.maxCoeff();
        p.sum[static_cast<std::size_t>(k)] = static_cast<double>(product.sum());
      }
    });
    double total = 0;
    for (double s : p.sum) total += s;
    return total;
  };
  p.total = reduce(p.both);
  if (!(p.total > 0) || !std::isfinite(p.total)) {
    p.both = false;
    p.total = reduce(p.both);
    if (!(p.total > 0) || !std::isfinite(p.total)) throw FilterError("smoothed_result: the forward belief has no mass");
  }
  return p;
}

// PAS and the sub-bin heading on gamma around the argmax (u*, v*, k*) in `result.argmax`, by the
// forward filter's own rules (StepDecisions::refine).
void refine_on_gamma(FrameResult& result, const BeliefVolume& forward, const BeliefVolume& backward, bool both,
                     int k_star, const FilterConfig& config) {
  auto gamma = [&](int u, int v, int k) {
    return static_cast<double>(forward.prob(u, v, k)) * (both ? backward.prob(u, v, k) : 1.0f);
  };
  const auto masses = [&](int u0, int v0, int u1, int v1, std::span<double> out) {
    std::size_t i = 0;
    for (int v = v0; v <= v1; ++v) {
      for (int u = u0; u <= u1; ++u) {
        double m = 0;
        for (int k = 0; k < forward.headings(); ++k) m += gamma(u, v, k);
        out[i++] = m;
      }
    }
  };
  result.pose = StepDecisions(config).refine(static_cast<int>(result.argmax.u), static_cast<int>(result.argmax.v),
                                             k_star, forward.width(), forward.height(), masses, gamma);
}

}  // namespace

FrameResult smoothed_result(const BeliefVolume& forward, const BeliefVolume& backward, const FilterConfig& config,
                            BeliefVolume* posterior) {
  check_shapes(forward, backward, posterior);
  const int W = forward.width(), R = forward.headings();
  const std::size_t n = forward.slice_cells();
  const SlicedProduct p = reduce_product(forward, backward, config, posterior);
  int k_star = 0;
  for (int k = 1; k < R; ++k) {
    if (p.best[static_cast<std::size_t>(k)] > p.best[static_cast<std::size_t>(k_star)]) k_star = k;
  }
  // The first cell of slice k* holding its largest product (as the forward filter's argmax).
  const float* a = forward.slice(k_star);
  const float* b = backward.slice(k_star);
  std::size_t cell = 0;
  for (std::size_t i = 0; i < n; ++i) {
    if ((p.both ? a[i] * b[i] : a[i]) == p.best[static_cast<std::size_t>(k_star)]) {
      cell = i;
      break;
    }
  }
  const int u_star = static_cast<int>(cell % static_cast<std::size_t>(W));
  const int v_star = static_cast<int>(cell / static_cast<std::size_t>(W));
  FrameResult result;
  result.argmax = {static_cast<double>(u_star), static_cast<double>(v_star), forward.bin_heading_deg(k_star)};
  result.pose = result.argmax;
  result.peak_log_belief = static_cast<float>(std::log(p.best[static_cast<std::size_t>(k_star)] / p.total));
  refine_on_gamma(result, forward, backward, p.both, k_star, config);
  return result;
}

}  // namespace seqloc::filter
