#pragma once
// The belief over a window of W x H cells (0.5 m) and R heading bins (conventions.md section 6).
//
// Stored as normalized probabilities in float, heading-major: slice k is one contiguous W x H
// image (row v, column u), so that motion, resampling and reductions run over long contiguous
// rows. The log-belief b of the conventions is log(prob); probabilities make the motion
// mass-preserving and MGR an affine blend, with no exp or log per cell. Float spans 87 nats below
// 1 (and the peak of a normalized belief is at least 1 / (W H R)), so only cells more than about
// 70 nats below the peak can round to zero.

#include <cstddef>
#include <vector>

#include "seqloc/filter/aligned.hpp"

namespace seqloc::filter {

/// Grid heading (degrees, clockwise) of bin k of `headings`: k * 360 / headings.
[[nodiscard]] inline double bin_heading_deg(int k, int headings) { return k * 360.0 / headings; }

class BeliefVolume {
 public:
  BeliefVolume(int width, int height, int headings);

  [[nodiscard]] int width() const { return width_; }
  [[nodiscard]] int height() const { return height_; }
  [[nodiscard]] int headings() const { return headings_; }
  [[nodiscard]] std::size_t slice_cells() const { return static_cast<std::size_t>(width_) * height_; }
  [[nodiscard]] std::size_t size() const { return data_.size(); }
  /// Grid heading (degrees, clockwise) of bin k.
  [[nodiscard]] double bin_heading_deg(int k) const { return filter::bin_heading_deg(k, headings_); }

  /// Probabilities of heading bin k, W x H row-major.
  [[nodiscard]] float* slice(int k) { return data_.data() + static_cast<std::size_t>(k) * slice_cells(); }
  [[nodiscard]] const float* slice(int k) const { return data_.data() + static_cast<std::size_t>(k) * slice_cells(); }
  [[nodiscard]] float& prob(int u, int v, int k) { return slice(k)[static_cast<std::size_t>(v) * width_ + u]; }
  [[nodiscard]] float prob(int u, int v, int k) const { return slice(k)[static_cast<std::size_t>(v) * width_ + u]; }
  /// The log-belief b(u, v, k) (-inf where the probability is 0).
  [[nodiscard]] double log_at(int u, int v, int k) const;
  [[nodiscard]] float* data() { return data_.data(); }
  [[nodiscard]] const float* data() const { return data_.data(); }

  /// Uniform over the window.
  void set_uniform();
  /// A Gaussian in position (sigma in cells) around (u, v), uniform in heading, normalized.
  void set_gaussian(double u, double v, double sigma_cells);
  /// The window moves by (du, dv) whole cells: the new cell (u, v) is the old (u + du, v + dv).
  /// Mass leaving the window is dropped; cells entering it get the window's current minimum
  /// (conventions.md section 6). The belief is not renormalized.
  void recentre(int du, int dv) { recentre(du, dv, min_value()); }
  /// The same with the entering cells' value given (the window's minimum where the caller keeps
  /// it), `threads` workers a slice each: rows moved whole, no pass over the belief to find it.
  void recentre(int du, int dv, float fill, int threads = 1);

  [[nodiscard]] float min_value() const;
  /// Sum of the probabilities (1 for a normalized belief).
  [[nodiscard]] double total_probability() const;
  /// Marginal over headings of one cell: sum_k prob(u, v, k).
  [[nodiscard]] double position_mass(int u, int v) const;
  /// The position marginal of every cell (summed over headings in double), W x H row-major.
  [[nodiscard]] std::vector<float> position_marginal() const;

 private:
  int width_, height_, headings_;
  AlignedVector<float> data_;
};

}  // namespace seqloc::filter
