#pragma once
// The cell work of a SeqLoc step behind one interface, and the values a step takes and gives.
// StepDecisions::step and ::update (step_decisions.hpp) run the step's sequence and make every
// decision in it; a backend (the CPU filter, the CUDA backend) provides only the passes over its
// belief and its frame, where they live.

#include <functional>
#include <optional>
#include <span>

#include "seqloc/filter/self_calibration.hpp"
#include "seqloc/filter/types.hpp"
#include "seqloc/intake/frame.hpp"

namespace seqloc::filter {

using intake::PreparedFrame;

/// How a step weighed its frame: the power self-calibration raised it to, ETU's weight, and the
/// peak log-probability of the frame so raised (the scale of its likelihood). A second pass over
/// the route (the smoother's, smoother.hpp) gives it to SeqLocFilter::update to multiply in the
/// very likelihood the first pass did, without estimating anything again.
struct FrameWeighting {
  double volume_power = 1;
  double etu_weight = 1;  ///< ETU's weight times self-calibration's for the frame's sharpness
  float peak_log_prob = 0;
};

/// A GPS fix in window cells, for the optional GPS prior term.
struct GpsFix {
  double u = 0, v = 0;
  double sigma_m = 10;
};

/// What a step takes besides the odometry: the frame's volume at `crop`, the road distance window
/// (W x H metres, row-major; empty when MGR is off) and, for the GPS term, a fix.
struct StepInput {
  const PreparedFrame& frame;
  const CropPose& crop;
  std::span<const float> road_distance_m;
  std::optional<GpsFix> gps;
};

struct FrameResult {
  Pose pose;    ///< the estimate: PAS's x_hat with th* (or the argmax when PAS is off)
  Pose argmax;  ///< (x*, th*)
  float peak_log_belief = 0;
  double frame_entropy = 0;  ///< H_hat of the frame's own volume, after self-calibration's power
  /// The weight used: ETU's (1 with ETU off) times self-calibration's for the frame's sharpness
  /// (2^StepDecisions::sharpness_octaves).
  double etu_weight = 1;
  /// The power self-calibration raised the frame to before ETU (1 with it off): the estimate from
  /// the frames before this one. For volumes sharpened as p^k it tends to 1 / k.
  double volume_power = 1;
  bool relocalized = false;  ///< the argmax jumped farther than the configured threshold
  FrameWeighting weighting;  ///< what the step multiplied in (volume_power and etu_weight again, and the scale)
};

/// What a step reads of a frame raised to a power: its peak log-probability and normalized entropy.
struct FrameShape {
  float max_log_prob = 0;
  double entropy = 0;
};

/// The belief's largest cell after an update.
struct BeliefPeak {
  int u = 0, v = 0, k = 0;
  float value = 0;
};

/// Fills `out` with the position masses m(x) = sum over th of the belief at x, for the cells
/// u0..u1 x v0..v1 (inclusive, row by row): each backend reads them where its belief lives.
using PositionMasses = std::function<void(int u0, int v0, int u1, int v1, std::span<double> out)>;
/// One cell of the belief (or of the smoother's product of two).
using CellValue = std::function<double(int u, int v, int k)>;

/// The passes of a step over a backend's belief and frame, in the order StepDecisions calls them.
class CellWork {
 public:
  virtual ~CellWork() = default;

  /// Predict: the belief warped backwards through the odometry (seqloc_filter.hpp).
  virtual void predict(const Odometry& odometry) = 0;
  /// A new frame: a backend that keeps it elsewhere loads it; `estimating`: the one-step estimator
  /// judges it after the update (the backend starts gathering its evidence).
  virtual void load(const PreparedFrame& frame, bool estimating) = 0;
  /// The frame raised to `power`: its peak and entropy (the frame's own at power 1). Called once a
  /// calibrating step, here or in temper(), where a backend also bins the frame's cells.
  virtual FrameShape powered_shape(const PreparedFrame& frame, double power) = 0;
  /// The belief raised to `ratio` and normalized (never at a route's first frame, never by 1).
  virtual void raise(float ratio) = 0;
  /// The tempered likelihood exp(exponent (log p - log p_max)) over the frame; with `shape_power`,
  /// powered_shape() at it, from the tempered frame where that is the powered one.
  virtual std::optional<FrameShape> temper(const PreparedFrame& frame, float exponent,
                                           std::optional<double> shape_power) = 0;
  /// The belief times the tempered frame sampled into the window (`outside` where a cell's centre
  /// is beyond the crop) and the GPS term (W x H, or empty); the frame alone without `with_prior`.
  /// Returns the belief's total. `pool`: the predicted belief is pooled for evidence() on the way.
  virtual double multiply_in(const PreparedFrame& frame, const CropPose& crop, float outside,
                             std::span<const float> gps_term, bool with_prior, bool pool) = 0;
  /// Self-calibration's evidence of the frame against the predicted belief pooled by multiply_in,
  /// kept by the backend until the next call (its bins are reused from frame to frame).
  virtual const CalibrationEvidence& evidence(const PreparedFrame& frame, const CropPose& crop) = 0;
  /// The belief divided by `total`, MGR's blend with the road prior of `road_distance_m` as the
  /// config asks, and its largest cell.
  virtual BeliefPeak normalize(double total, std::span<const float> road_distance_m) = 0;
  /// The belief's position masses and cells, for PAS and the sub-bin heading.
  [[nodiscard]] virtual PositionMasses position_masses() = 0;
  [[nodiscard]] virtual CellValue cell_value() = 0;

  /// Self-calibration's bank (FilterConfig::self_calibration_bank), for a backend that runs one:
  /// the power it favours now, and each calibrating frame judged after the update.
  [[nodiscard]] virtual std::optional<double> bank_power() const { return std::nullopt; }
  virtual void bank_judge(const PreparedFrame& /*frame*/, const CropPose& /*crop*/, double /*etu_weight*/) {}
};

}  // namespace seqloc::filter
