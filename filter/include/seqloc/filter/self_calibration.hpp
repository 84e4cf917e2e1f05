#pragma once
// Self-calibration's estimator (the power's posterior from the frames' depth histograms) is the
// selfcal module's (selfcal/estimator.hpp); the filter gathers its evidence (calibration_evidence.hpp)
// and names it as its own.

#include "seqloc/selfcal/estimator.hpp"

namespace seqloc::filter {

using selfcal::CalibrationEvidence;
using selfcal::DepthHistogram;
using selfcal::EstimatorError;
using selfcal::PowerEstimator;

}  // namespace seqloc::filter
