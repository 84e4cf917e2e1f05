// seqloc: sequence localization against OpenStreetMap. Subcommands are classes in cmd_*.cpp.

#include <unistd.h>
#include <cstdio>
#include <exception>
#include <memory>
#include <string>
#include <vector>

#include "command.hpp"
#include "seqloc/core/error.hpp"

namespace seqloc::app {

bool WithProgress::show_progress() const {
  if (progress_ > 0) return true;
  if (progress_ < 0) return false;
  return isatty(STDERR_FILENO) != 0;
}

void WithOverwrite::check_overwrite(const std::filesystem::path& out) const {
  std::error_code ec;
  if (std::filesystem::exists(out, ec) && !overwrite_) {
    throw seqloc::UsageError(out.string() + ": already exists; pass --overwrite to replace it");
  }
}

void ProgressBar::update(long long done, long long total) {
  if (!enabled_) return;
  const auto now = std::chrono::steady_clock::now();
  if (done < total && now - last_ < std::chrono::milliseconds(200)) return;
  last_ = now;
  const double elapsed = std::chrono::duration<double>(now - start_).count();
  const double fraction = total > 0 ? static_cast<double>(done) / static_cast<double>(total) : 1.0;
  const double rate = elapsed > 0 ? static_cast<double>(done) / elapsed : 0.0;
  const double eta = rate > 0 ? static_cast<double>(total - done) / rate : 0.0;
  constexpr int kWidth = 30;
  const int filled = static_cast<int>(fraction * kWidth);
  std::fprintf(stderr, "\r%s [%.*s%*s] %lld/%lld %.0f/s ETA %.0fs ", label_.c_str(), filled,
               "##############################", kWidth - filled, "", done, total, rate, eta);
  std::fflush(stderr);
  drawn_ = true;
}

void ProgressBar::done() {
  if (drawn_) std::fputc('\n', stderr);
  drawn_ = false;
}

}  // namespace seqloc::app

int main(int argc, char** argv) {
  namespace app = seqloc::app;
  CLI::App cli{
      "seqloc: localize vehicles against OpenStreetMap with sequences of pose likelihoods.\n"
      "Map data (c) OpenStreetMap contributors, ODbL 1.0."};
  cli.name("seqloc");
  cli.require_subcommand(1);
  cli.set_version_flag("--version", std::string("seqloc ") + SEQLOC_VERSION);
  app::GlobalOptions global;
  // Global options, before the subcommand or after it (seqloc -v localize ..., seqloc localize ... -v).
  const auto add_global_options = [&global](CLI::App& app) {
    app.add_flag("-v,--verbose", global.verbose, "Timestamped log lines on stderr");
  };
  add_global_options(cli);

  std::vector<std::pair<CLI::App*, std::unique_ptr<app::Command>>> commands;
  auto add = [&](CLI::App* parent, const char* name, const char* description, std::unique_ptr<app::Command> command) {
    CLI::App* sub = parent->add_subcommand(name, description);
    add_global_options(*sub);
    command->set_global(&global);
    command->declare(*sub);
    commands.emplace_back(sub, std::move(command));
  };
  add(&cli, "preprocess", "Build a region cache (GeoPackage) from an OSM file", app::make_preprocess_command());
  add(&cli, "update", "Apply an OSM change file to a region cache, re-rendering only the tiles it touches",
      app::make_update_command());
  add(&cli, "localize", "Localize routes against a region cache", app::make_localize_command());
  add(&cli, "evaluate", "Recompute the recall table from localize outputs", app::make_evaluate_command());
  add(&cli, "simulate", "Simulate routes with BEV observations along a cache's roads", app::make_simulate_command());
  add(&cli, "match", "Write the built-in matcher's volumes of observation routes as volume routes",
      app::make_match_command());
  add(&cli, "calibrate", "Fit a backbone's temperature, blur and floor on routes with ground truth",
      app::make_calibrate_command());
  add(&cli, "render", "Draw figures of a route: likelihood vs belief, entropy, error over time",
      app::make_render_command());
  add(&cli, "serve", "Serve region caches over HTTP: tiles, crops, points, WMTS, the viewer page",
      app::make_serve_command());
  add(&cli, "export",
      "Export a layer of a region cache as a Cloud Optimized GeoTIFF or as a PMTiles or MBTiles map, or the cache as a "
      "VRT",
      app::make_export_command());
  CLI::App* cache = cli.add_subcommand("cache", "Inspect and combine region caches");
  cache->require_subcommand(1);
  add_global_options(*cache);
  add(cache, "info", "Print a cache's metadata", app::make_cache_info_command());
  add(cache, "merge", "Merge the shards of a sharded build into one cache", app::make_cache_merge_command());

  try {
    try {
      cli.parse(argc, argv);  // and each parsed command's check()
    } catch (const CLI::ParseError& e) {
      const int code = cli.exit(e);
      return code == 0 ? app::kExitOk : app::kExitUsage;
    }
    for (auto& [sub, command] : commands) {
      if (sub->parsed()) return command->run();
    }
    return app::kExitUsage;
  } catch (const std::exception& e) {
    // One line naming what is wrong; the exit code from the error's category alone.
    std::fprintf(stderr, "seqloc: error: %s\n", e.what());
    return app::exit_code(seqloc::category_of(e));
  }
}
