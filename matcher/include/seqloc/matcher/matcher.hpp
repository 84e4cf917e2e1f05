#pragma once
// The built-in backbone: scores a BEV observation against the cached class raster at every
// position and heading of a crop, and returns a pose likelihood volume in the layout of
// conventions.md section 4 (docs/matcher.md).
//
// The score of a pose is the log-likelihood of the visible observed cells given the map placed
// under them, with a per-channel confusion model (missed classes, spurious detections, wrong
// classes) and a positional tolerance (the map's class indicators blurred by a Gaussian), divided
// by a temperature that accounts for neighbouring cells not being independent. As OrienterNet
// scores its templates, it is one FFT correlation per heading: the observation is rotated, the
// map is not. Rotations by a multiple of 90 degrees are exact array rotations, so only a quarter
// of the headings need rotated templates and their transforms.

#include <array>
#include <cstdint>
#include <span>
#include <utility>
#include <vector>

#include "seqloc/io/observation.hpp"
#include "seqloc/matcher/calibration.hpp"

namespace seqloc::matcher {

struct MatcherConfig {
  int size = 128;      ///< the volume's side H = W in 0.5 m cells (even)
  int headings = 256;  ///< N heading bins (a multiple of 4)
  /// The log-likelihood is divided by this. 3, with the calibration below, is the fit of
  /// bench/calibrate on development routes (docs/matcher.md, "Calibration").
  double temperature = 3.0;
  double miss_rate = 0.75;      ///< P(observed background | the map has a class there); see docs/matcher.md
  double spurious_rate = 0.05;  ///< P(observed some class | the map has background)
  double confusion_rate = 0.1;  ///< P(observed another class of the channel | the map has a class)
  double tolerance_m = 1.0;     ///< sigma of the Gaussian that blurs the map's class indicators
  /// Applied by localize to each volume after the temperature (calibration.hpp; docs/matcher.md):
  /// blur of 3 cells (1.5 m) and 2 bins (2.8 degrees), half the mass spread uniformly.
  VolumeCalibration calibration{3.0, 2.0, 0.5};
  int threads = 1;

  /// Throws UsageError naming the bad field.
  void validate() const;
};

class BevMatcher {
 public:
  explicit BevMatcher(const MatcherConfig& config);

  [[nodiscard]] const MatcherConfig& config() const { return config_; }

  /// Side of the map crop needed for an observation of side `observation_size`: the volume's
  /// side plus the observation's, minus one. The crop's centre (a cell corner) is the volume's.
  [[nodiscard]] int map_side(int observation_size) const { return config_.size + observation_size - 1; }

  /// The volume (size, size, headings), float32 log-likelihoods (not normalized), grid north:
  /// bin k is the grid heading k * 360 / headings. `map_rgb` is the north-up class crop of side
  /// map_side(observation.size), RGB interleaved. Throws UsageError on a size mismatch.
  [[nodiscard]] std::vector<float> match(const io::Observation& observation,
                                         std::span<const std::uint8_t> map_rgb) const;

  /// The per-cell score of observing code `observed` of `channel` where the map's soft class
  /// indicators are `map_share` (one share per code of the channel, summing to 1), before the
  /// temperature: log P(observed | map) - log P(observed | background).
  [[nodiscard]] double cell_score(int channel, int observed, std::span<const double> map_share) const;

  /// The map term of one observed code over a map crop: cell_score with the blurred indicators,
  /// side * side values, row-major.
  [[nodiscard]] std::vector<float> map_term(int channel, int observed, std::span<const std::uint8_t> map_rgb,
                                            int side) const;

  /// The observation's indicator of one code, visible cells only, rotated to grid heading
  /// `heading_deg` (clockwise) about the camera and sampled bilinearly: the template laid on the
  /// map, north-up, observation.size squared values.
  [[nodiscard]] std::vector<float> rotated_template(const io::Observation& observation, int channel, int code,
                                                    double heading_deg) const;

  /// The (channel, code) pairs seen in the observation's visible cells, background included.
  [[nodiscard]] static std::vector<std::array<int, 2>> observed_codes(const io::Observation& observation);

 private:
  /// The bodies (visible disc, then one indicator per observed code beyond each channel's first)
  /// and the map term each is correlated with (match()'s reference-code decomposition).
  [[nodiscard]] std::pair<std::vector<std::vector<float>>, std::vector<std::vector<float>>> correlands(
      const io::Observation& observation, std::span<const std::uint8_t> map_rgb, int side) const;
  MatcherConfig config_;
  std::array<std::vector<double>, 3> likelihood_;  ///< [channel][observed * (K+1) + map] = P(o | m)
};

}  // namespace seqloc::matcher
