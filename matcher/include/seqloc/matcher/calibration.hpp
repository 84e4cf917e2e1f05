#pragma once
// Calibration of a backbone's pose likelihood volumes (docs/matcher.md, "Calibration"): a volume
// is a probability the way a network trained with NLL over H x W x N makes it one when the true
// pose gets, on average, the density the volume claims. Three corrections are fitted by the mean
// negative log-likelihood of the true cell on development routes:
//   p'(x) = (1 - a) * normalize(blur(exp(s(x) / T))) + a / M
// with T the temperature of the scores s, a Gaussian blur in position (sigma in cells) and in
// heading (sigma in bins, circular) for pose jitter the scores do not model, and a floor a for
// frames that show another place or miss what they should see.

#include <cstddef>
#include <span>
#include <vector>

namespace seqloc::matcher {

/// The corrections applied after the temperature (which the matcher's config holds).
struct VolumeCalibration {
  double blur_cells = 0;  ///< sigma of the positional Gaussian, in cells (0: none)
  double blur_bins = 0;   ///< sigma of the heading Gaussian, in bins, circular (0: none)
  double floor = 0;       ///< a in [0, 1): the share of mass spread uniformly

  [[nodiscard]] bool identity() const { return blur_cells == 0 && blur_bins == 0 && floor == 0; }
  /// Throws UsageError naming the bad field.
  void validate() const;
};

/// Turns an (H, W, N) volume of log-likelihoods (any offset) into calibrated, normalized
/// log-probabilities, in place. Kernels are truncated at 3 sigma; mass blurred past the crop's
/// edge is dropped and the rest renormalized. `threads` share the work (the result is the same).
void calibrate_volume(std::span<float> volume, int height, int width, int bins, const VolumeCalibration& calibration,
                      int threads = 1);

/// calibrate_volume for a volume stored heading-major ([bin][v][u], a prepared frame's layout):
/// the same blurs, floor and logs, so that a frame is calibrated where it is, not turned back to
/// (H, W, N) and prepared again. Equal to calibrate_volume of the same volume to float rounding
/// (the sum that normalizes it is taken in this layout's order); the same for any `threads`.
void calibrate_heading_major(std::span<float> volume, int bins, int height, int width,
                             const VolumeCalibration& calibration, int threads = 1);

/// The discrete Gaussian used by calibrate_volume: 2 * ceil(3 sigma) + 1 taps summing to 1
/// (one tap of 1 for sigma 0).
[[nodiscard]] std::vector<double> gaussian_taps(double sigma);

/// Fits T, blur and floor by the mean NLL of the true cell over many frames. Frames are added one
/// at a time (only a window around the true cell and one normalizer per temperature are kept), so
/// a fit over thousands of frames needs little memory.
class CalibrationFit {
 public:
  struct Grid {
    std::vector<double> temperatures{2, 3, 4, 5, 6, 8, 10, 12, 16, 24, 32};
    std::vector<double> blur_cells{0, 1, 2, 3, 4, 5};
    std::vector<double> blur_bins{0, 1, 2, 3, 4, 6};
    std::vector<double> floors{0, 1e-4, 1e-3, 3e-3, 1e-2, 3e-2, 0.1, 0.2, 0.3, 0.4, 0.5, 0.6, 0.7};
  };
  struct Result {
    double temperature = 1;
    VolumeCalibration calibration;
    double nll = 0;           ///< mean NLL of the true cell (nats)
    double uniform_nll = 0;   ///< the same for a uniform volume: log M
    std::size_t frames = 0;   ///< frames whose true cell lies in the volume
    std::size_t skipped = 0;  ///< frames whose true cell lies outside it
  };

  CalibrationFit();  ///< the default grid
  explicit CalibrationFit(Grid grid);

  /// `scores`: (H, W, N) raw log-likelihood scores (temperature 1). The true pose is cell (v, u)
  /// and bin b, nearest; a true cell outside the volume is counted as skipped.
  void add(std::span<const float> scores, int height, int width, int bins, int true_v, int true_u, int true_bin);

  /// Mean NLL of the true cell for one setting (temperature from the grid's list).
  [[nodiscard]] double mean_nll(double temperature, const VolumeCalibration& calibration) const;
  /// The setting of the grid with the least mean NLL.
  [[nodiscard]] Result best() const;
  [[nodiscard]] const Grid& grid() const { return grid_; }

 private:
  struct Frame {
    double log_cells = 0;
    std::vector<double> log_z;  ///< per temperature: log sum exp(s / T)
    std::vector<float> window;  ///< scores around the true cell; NaN outside the volume
  };
  [[nodiscard]] double blurred_at_truth(const Frame& frame, std::size_t t, double blur_cells, double blur_bins) const;

  Grid grid_;
  int radius_cells_ = 0, radius_bins_ = 0;
  std::vector<Frame> frames_;
  std::size_t skipped_ = 0;
};

}  // namespace seqloc::matcher
