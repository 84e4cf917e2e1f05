#include <algorithm>
#include <initializer_list>
#include <string>
#include <string_view>
#include <type_traits>
#include <variant>

#include "command.hpp"
#include "seqloc/matcher/matcher.hpp"

namespace seqloc::app {
namespace {

// The shorter name an earlier release gave a field's option, where there is one.
const char* historic_name(std::string_view field) {
  if (field == "mgr_epsilon") return "--epsilon";
  if (field == "mgr_sigma_m") return "--sigma";
  if (field == "etu_reference_entropy") return "--etu-reference";
  return nullptr;
}

}  // namespace

void add_filter_options(CLI::App& app, filter::FilterConfig& config, std::initializer_list<std::string_view> skip) {
  const filter::FilterConfig defaults;
  for (const auto& field : filter::filter_config_fields()) {
    if (std::find(skip.begin(), skip.end(), field.name) != skip.end()) continue;
    std::string flag = field.name;
    for (char& c : flag) c = c == '_' ? '-' : c;
    std::visit(
        [&](auto member) {
          using Value = std::remove_reference_t<decltype(config.*member)>;
          if constexpr (std::is_same_v<Value, bool>) {
            if (defaults.*member) {
              app.add_flag("!--no-" + flag, config.*member, std::string("Switch off ") + field.help);
            } else {
              app.add_flag("--" + flag, config.*member, field.help);
            }
          } else {
            const char* old = historic_name(field.name);
            app.add_option((old ? std::string(old) + "," : std::string()) + "--" + flag, config.*member, field.help)
                ->capture_default_str();
          }
        },
        field.member);
  }
  // Defined after the fields' options, so its callback runs after theirs and wins.
  app.add_flag_callback(
      "--paper",
      [&config, defaults] {
        // The fields in which the paper's configuration differs from the defaults.
        const filter::FilterConfig paper = filter::paper_config();
        for (const auto& field : filter::filter_config_fields()) {
          std::visit(
              [&](auto member) {
                if (paper.*member != defaults.*member) config.*member = paper.*member;
              },
              field.member);
        }
      },
      "The seed paper's configuration (conventions.md section 6): --etu-reference 0 --outside-crop-nats 0 "
      "--no-self-calibrate, whatever those options say");
}

void add_matcher_options(CLI::App& app, matcher::MatcherConfig& m) {
  app.add_option("--matcher-size", m.size, "Built-in matcher (observation routes): volume side in cells")
      ->capture_default_str();
  app.add_option("--matcher-temperature", m.temperature, "Built-in matcher: the log-likelihood is divided by this")
      ->capture_default_str();
  app.add_option("--matcher-tolerance", m.tolerance_m, "Built-in matcher: positional tolerance (sigma, m)")
      ->capture_default_str();
  app.add_option("--matcher-blur-cells", m.calibration.blur_cells,
                 "Built-in matcher calibration: positional blur of the volume (sigma, cells)")
      ->capture_default_str();
  app.add_option("--matcher-blur-bins", m.calibration.blur_bins,
                 "Built-in matcher calibration: heading blur of the volume (sigma, bins)")
      ->capture_default_str();
  app.add_option("--matcher-floor", m.calibration.floor,
                 "Built-in matcher calibration: share of each volume spread uniformly")
      ->capture_default_str();
}

}  // namespace seqloc::app
