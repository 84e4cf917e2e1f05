#include <algorithm>
#include <initializer_list>
#include <string>
#include <string_view>
#include <type_traits>
#include <variant>

#include "command.hpp"

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
}

}  // namespace seqloc::app
