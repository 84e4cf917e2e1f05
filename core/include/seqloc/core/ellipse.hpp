#pragma once
// The ellipses of a 2-D Gaussian (an estimate's position covariance): the one test of whether an
// offset lies within the ellipse of probability p, which the filter's uncertainty and the metrics
// of a run (io) both use.

#include <cmath>

namespace seqloc::core {

/// The squared Mahalanobis radius of a 2-D Gaussian's ellipse of probability `p`: the chi-square
/// quantile with 2 degrees of freedom, -2 ln(1 - p).
[[nodiscard]] inline double chi2_2(double p) { return -2 * std::log1p(-p); }

/// Whether offset (d_east, d_north) lies inside the covariance's ellipse of probability `p`
/// (its squared Mahalanobis distance at most chi2_2(p)). A degenerate covariance holds its centre
/// alone.
[[nodiscard]] inline bool inside_ellipse(double cov_ee, double cov_en, double cov_nn, double d_east, double d_north,
                                         double p) {
  const double det = cov_ee * cov_nn - cov_en * cov_en;
  if (!(det > 0)) return d_east == 0 && d_north == 0;
  const double q = (cov_nn * d_east * d_east - 2 * cov_en * d_east * d_north + cov_ee * d_north * d_north) / det;
  return q <= chi2_2(p);
}

}  // namespace seqloc::core
