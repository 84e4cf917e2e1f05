#pragma once
// One class per subcommand (osmium-tool's Command): setup() declares the options, check()
// validates what was parsed (before any work: a usage error never leaves output behind), run()
// does the work. main() turns exceptions into one line on stderr and an exit code.

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <filesystem>
#include <initializer_list>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include <CLI/CLI.hpp>

#include "seqloc/core/error.hpp"
#include "seqloc/core/thread_pool.hpp"
#include "seqloc/filter/config.hpp"
#include "seqloc/osm/features.hpp"

namespace seqloc::raster {
class CacheReader;
}  // namespace seqloc::raster
namespace seqloc::io {
struct Route;
struct RouteLimits;
}  // namespace seqloc::io
namespace seqloc::matcher {
struct MatcherConfig;
}  // namespace seqloc::matcher
namespace seqloc::pipeline {
struct LocalizeOptions;
}  // namespace seqloc::pipeline

namespace seqloc::app {

using core::default_threads;

/// Exit codes: 0 success, 1 failure (bad data, I/O), 2 usage.
inline constexpr int kExitOk = 0;
inline constexpr int kExitFailure = 1;
inline constexpr int kExitUsage = 2;

/// The exit code of an error's category: 2 for a usage error (an option, a value), 1 for the rest
/// (what is not there, bad data, I/O, a bug of ours).
[[nodiscard]] constexpr int exit_code(ErrorCategory category) {
  switch (category) {
    case ErrorCategory::usage:
      return kExitUsage;
    case ErrorCategory::not_found:
    case ErrorCategory::data:
    case ErrorCategory::io:
    case ErrorCategory::internal:
      break;
  }
  return kExitFailure;
}

/// Options every subcommand shares.
struct GlobalOptions {
  bool verbose = false;
};

class Command {
 public:
  virtual ~Command() = default;
  /// Declares the subcommand's options on `app` (setup) and has the parse validate them (check):
  /// a usage error comes out of CLI::App::parse, before run() is called.
  void declare(CLI::App& app) {
    setup(app);
    app.final_callback([this] { check(); });
  }
  /// Does the work; returns the exit code. Throws on failure.
  virtual int run() = 0;

  void set_global(const GlobalOptions* global) { global_ = global; }

 protected:
  /// A timestamped log line on stderr, shown with -v.
  template <class... Args>
  void log(const char* format, Args... args) const {
    if (!global_ || !global_->verbose) return;
    const auto now = std::chrono::system_clock::to_time_t(std::chrono::system_clock::now());
    char stamp[32];
    std::strftime(stamp, sizeof stamp, "%Y-%m-%d %H:%M:%S", std::localtime(&now));
    std::fprintf(stderr, "[%s] ", stamp);
    if constexpr (sizeof...(Args) == 0) {
      std::fputs(format, stderr);
    } else {
      std::fprintf(stderr, format, args...);
    }
    std::fputc('\n', stderr);
  }

  /// Declares the subcommand's options on `app`.
  virtual void setup(CLI::App& app) = 0;
  /// Validates the parsed options (their values, and whether the output may be written); throws
  /// seqloc::UsageError naming the option. Reads no input, writes nothing.
  virtual void check() {}

  const GlobalOptions* global_ = nullptr;
};

/// An option for every field of `config` but those named in `skip`, from the filter's field table
/// (filter::filter_config_fields): --NAME in kebab case (and the shorter name of earlier releases),
/// with the field's help and its default; a switch that is on by default is --no-NAME. --paper sets
/// the fields in which filter::paper_config() differs from the defaults.
void add_filter_options(CLI::App& app, filter::FilterConfig& config, std::initializer_list<std::string_view> skip);

/// The built-in matcher's options (--matcher-*), for the commands that score observations.
void add_matcher_options(CLI::App& app, matcher::MatcherConfig& matcher);

/// --max-step, --max-speed and --max-yaw: the odometry's plausibility limits (io::RouteLimits),
/// the same for every command that reads routes.
void add_route_limit_options(CLI::App& app, io::RouteLimits& limits);

/// The routes of `dirs`, read with `limits` (io::read_routes) and checked (their crops against the
/// region) before any work. Throws DataError naming the file and line.
[[nodiscard]] std::vector<io::Route> read_checked_routes(const std::vector<std::filesystem::path>& dirs,
                                                         const io::RouteLimits& limits, raster::CacheReader& cache,
                                                         const pipeline::LocalizeOptions& options);

/// Runs `validate` (the checks of option values): whatever it throws is a usage error (exit 2),
/// the options being wrong, not the data.
template <class Validate>
void validate_options(Validate&& validate) {
  try {
    std::forward<Validate>(validate)();
  } catch (const std::exception& e) {
    throw seqloc::UsageError(e.what());
  }
}

/// --overwrite for the commands that write an output (osmium-tool's option mixins).
class WithOverwrite {
 protected:
  void add_overwrite_option(CLI::App& app, const std::string& what) {
    app.add_flag("--overwrite", overwrite_, "Replace an existing " + what);
  }
  /// Throws UsageError naming `out` when it exists and --overwrite was not given.
  void check_overwrite(const std::filesystem::path& out) const;
  bool overwrite_ = false;
};

/// --progress / --no-progress for the commands with long work.
class WithProgress {
 protected:
  void add_progress_option(CLI::App& app) {
    app.add_flag("--progress,!--no-progress", progress_, "Show progress on stderr (default: when it is a terminal)");
  }
  /// Whether to draw progress: the flag, else whether stderr is a terminal.
  [[nodiscard]] bool show_progress() const;
  int progress_ = 0;
};

/// A one-line progress bar on stderr, drawn only when wanted (a terminal, or --progress).
class ProgressBar {
 public:
  ProgressBar(bool enabled, std::string label) : enabled_(enabled), label_(std::move(label)) {}
  ~ProgressBar() { done(); }
  void update(long long done, long long total);
  void done();

 private:
  bool enabled_;
  bool drawn_ = false;
  std::string label_;
  std::chrono::steady_clock::time_point start_ = std::chrono::steady_clock::now();
  std::chrono::steady_clock::time_point last_{};
};

/// "lon0,lat0,lon1,lat1" in decimal degrees; throws UsageError naming the option otherwise.
osm::GeoBox parse_bbox(const std::string& text);

/// `text` as exactly `count` numbers separated by `separator`, each read whole by std::from_chars
/// (no locale, no partial match, no silent overflow; floating point must be finite); nullopt
/// otherwise. Option values like "0/4" or "2,0.1" go through here, not sscanf.
template <class T>
std::optional<std::vector<T>> parse_numbers(std::string_view text, char separator, std::size_t count) {
  std::vector<T> out;
  while (true) {
    const std::size_t end = std::min(text.find(separator), text.size());
    T value{};
    const auto [last, ec] = std::from_chars(text.data(), text.data() + end, value);
    if (end == 0 || ec != std::errc() || last != text.data() + end) return std::nullopt;
    if constexpr (std::is_floating_point_v<T>) {
      if (!std::isfinite(value)) return std::nullopt;
    }
    out.push_back(value);
    if (end == text.size()) break;
    text.remove_prefix(end + 1);
  }
  if (out.size() != count) return std::nullopt;
  return out;
}

std::unique_ptr<Command> make_preprocess_command();
std::unique_ptr<Command> make_update_command();
std::unique_ptr<Command> make_cache_info_command();
std::unique_ptr<Command> make_cache_merge_command();
std::unique_ptr<Command> make_localize_command();
std::unique_ptr<Command> make_evaluate_command();
std::unique_ptr<Command> make_simulate_command();
std::unique_ptr<Command> make_match_command();
std::unique_ptr<Command> make_calibrate_command();
std::unique_ptr<Command> make_render_command();
std::unique_ptr<Command> make_serve_command();
std::unique_ptr<Command> make_export_command();

}  // namespace seqloc::app
