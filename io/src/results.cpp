#include "seqloc/io/results.hpp"

#include <algorithm>
#include <cmath>

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

}  // namespace seqloc::io
