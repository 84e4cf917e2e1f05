#include "seqloc/io/results.hpp"

#include <algorithm>
#include <cmath>
#include <optional>

#include "seqloc/core/ellipse.hpp"

namespace seqloc::io {

const char* mode_name(Mode mode) {
  switch (mode) {
    case Mode::seqloc:
      return "seqloc";
    case Mode::online:
      return "online";
    case Mode::offline:
      return "offline";
    case Mode::smooth:
      return "smooth";
    case Mode::single:
      break;
  }
  return "single";
}

std::optional<Mode> parse_mode(std::string_view name) {
  for (const Mode mode : kModes) {
    if (name == mode_name(mode)) return mode;
  }
  return std::nullopt;
}

Metrics compute_metrics(std::span<const FramePose> poses) {
  Metrics m;
  std::vector<double> position, heading;
  double lateral = 0, longitudinal = 0;
  std::size_t body = 0;
  for (const FramePose& p : poses) {
    if (!p.position_error_m) continue;
    position.push_back(*p.position_error_m);
    if (p.heading_error_deg) heading.push_back(*p.heading_error_deg);
    if (p.lateral_error_m) {
      lateral += std::abs(*p.lateral_error_m);
      longitudinal += std::abs(*p.longitudinal_error_m);
      ++body;
    }
  }
  m.frames = position.size();
  auto fill = [](std::vector<double>& errors, double* recall, double& mean, double& median,
                 std::initializer_list<double> thresholds) {
    if (errors.empty()) return;
    int i = 0;
    for (double t : thresholds) {
      recall[i++] = 100.0 *
                    static_cast<double>(std::count_if(errors.begin(), errors.end(), [t](double e) { return e < t; })) /
                    static_cast<double>(errors.size());
    }
    double sum = 0;
    for (double e : errors) sum += e;
    mean = sum / static_cast<double>(errors.size());
    std::sort(errors.begin(), errors.end());
    const std::size_t n = errors.size();
    median = n % 2 ? errors[n / 2] : (errors[n / 2 - 1] + errors[n / 2]) / 2;
  };
  fill(position, m.position_recall, m.mean_position_error_m, m.median_position_error_m, {1.0, 3.0, 5.0});
  fill(heading, m.heading_recall, m.mean_heading_error_deg, m.median_heading_error_deg, {1.0, 3.0, 5.0});
  if (body > 0) {
    m.mean_abs_lateral_m = lateral / static_cast<double>(body);
    m.mean_abs_longitudinal_m = longitudinal / static_cast<double>(body);
  }
  return m;
}

std::optional<UncertaintyCalibration> uncertainty_calibration(std::span<const FramePose> poses) {
  UncertaintyCalibration c;
  std::size_t inside = 0;
  std::array<double, 10> reported{}, within{};
  for (const FramePose& p : poses) {
    if (!p.truth || !p.uncertainty) continue;
    const auto& u = *p.uncertainty;
    const double de = p.truth->x_m - p.x_m, dn = p.truth->y_m - p.y_m;
    inside += core::inside_ellipse(u.cov_xx_m2, u.cov_xy_m2, u.cov_yy_m2, de, dn, 0.95) ? 1 : 0;
    const auto bin = static_cast<std::size_t>(std::clamp(u.mass_within_5m * 10, 0.0, 9.0));
    ++c.reliability[bin].frames;
    reported[bin] += u.mass_within_5m;
    within[bin] += std::hypot(de, dn) <= 5.0 ? 1.0 : 0.0;
    ++c.frames;
  }
  if (c.frames == 0) return std::nullopt;
  const auto n = static_cast<double>(c.frames);
  c.coverage_95_pct = 100.0 * static_cast<double>(inside) / n;
  for (std::size_t b = 0; b < c.reliability.size(); ++b) {
    auto& bin = c.reliability[b];
    if (bin.frames == 0) continue;
    const auto k = static_cast<double>(bin.frames);
    bin.reported_pct = 100.0 * reported[b] / k;
    bin.actual_pct = 100.0 * within[b] / k;
    c.mass_5m_ece_pts += k / n * std::abs(bin.reported_pct - bin.actual_pct);
  }
  return c;
}

}  // namespace seqloc::io
