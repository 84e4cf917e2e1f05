#pragma once
// The belief: log-probabilities over a window of W x H cells (0.5 m) and R heading bins
// (conventions.md section 6). Stored heading-major: slice k is one contiguous W x H image
// (row v, column u), so that motion, resampling and reductions run over long contiguous rows.

#include <cstddef>
#include <cstdint>
#include <vector>

namespace seqloc::filter {

class BeliefVolume {
 public:
  BeliefVolume(int width, int height, int headings);

  [[nodiscard]] int width() const { return width_; }
  [[nodiscard]] int height() const { return height_; }
  [[nodiscard]] int headings() const { return headings_; }
  [[nodiscard]] std::size_t slice_cells() const { return static_cast<std::size_t>(width_) * height_; }
  [[nodiscard]] std::size_t size() const { return data_.size(); }
  /// Grid heading (degrees, clockwise) of bin k.
  [[nodiscard]] double bin_heading_deg(int k) const { return k * 360.0 / headings_; }

  [[nodiscard]] float* slice(int k) { return data_.data() + static_cast<std::size_t>(k) * slice_cells(); }
  [[nodiscard]] const float* slice(int k) const { return data_.data() + static_cast<std::size_t>(k) * slice_cells(); }
  [[nodiscard]] float& at(int u, int v, int k) { return slice(k)[static_cast<std::size_t>(v) * width_ + u]; }
  [[nodiscard]] float at(int u, int v, int k) const { return slice(k)[static_cast<std::size_t>(v) * width_ + u]; }
  [[nodiscard]] float* data() { return data_.data(); }
  [[nodiscard]] const float* data() const { return data_.data(); }

  /// Uniform over the window.
  void set_uniform();
  /// A Gaussian in position (sigma in cells) around (u, v), uniform in heading, normalized.
  void set_gaussian(double u, double v, double sigma_cells);
  /// The window moves by (du, dv) whole cells: the new cell (u, v) is the old (u + du, v + dv).
  /// Mass leaving the window is dropped; cells entering it get the window's current minimum
  /// (conventions.md section 6). The belief is not renormalized.
  void recentre(int du, int dv);

  [[nodiscard]] float min_value() const;
  /// Sum of exp over all cells (1 for a normalized belief).
  [[nodiscard]] double total_probability() const;
  /// Marginal over headings of one cell: sum_k exp(b(u, v, k)).
  [[nodiscard]] double position_mass(int u, int v) const;

 private:
  int width_, height_, headings_;
  std::vector<float> data_;
};

}  // namespace seqloc::filter
