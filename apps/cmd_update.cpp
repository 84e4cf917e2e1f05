#include <cstdio>
#include <filesystem>
#include <string>

#include "command.hpp"
#include "seqloc/ingest/update.hpp"

namespace seqloc::app {
namespace {

// seqloc update: an OSM change file applied to a region cache, re-rendering only the tiles it can
// alter (docs/preprocess.md, "Keeping a cache current").
class UpdateCommand : public Command, public WithProgress {
 public:
  void setup(CLI::App& app) override {
    app.add_option("cache", options_.cache, "Region cache built from --base (complete, unsharded)")->required();
    app.add_option("--base", options_.base, "The OSM file the cache was built from (its SHA-256 is checked)")
        ->required();
    app.add_option("--changes", options_.changes,
                   "OSM change file bringing the base to the new state: .osc, .osc.gz or .osc.bz2 (a replication "
                   "diff, or osmium derive-changes output)")
        ->required();
    app.add_option("--state", options_.state,
                   "The change's replication state, recorded in the cache and the new base: the server's "
                   "state.txt (beside each diff) or the sequence file pyosmium-get-changes -f writes. Without it "
                   "the updated cache records no replication sequence or timestamp");
    app.add_option("-o,--output", options_.output, "Write the updated cache here instead of replacing CACHE");
    app.add_option("--new-base", options_.new_base,
                   "Keep the new state of the data here (.osm.pbf): the base of the next update");
    app.add_option("--threads", options_.threads, "Worker threads (0: all cores)")
        ->capture_default_str()
        ->check(CLI::NonNegativeNumber);
    add_progress_option(app);
    app.footer(
        "The updated cache equals, tile for tile, the one seqloc preprocess builds from the new data over the same\n"
        "box. It is written whole or not at all: on any error CACHE is left as it was. The change file must apply\n"
        "to the base (no modify of an object the base lacks, no versions going backwards).");
  }

  void check() override {
    options_.validate();
    std::error_code ec;
    if (!options_.output.empty() && std::filesystem::exists(options_.output, ec)) {
      throw seqloc::UsageError(options_.output.string() + ": already exists (give another -o, or none to update " +
                               options_.cache.string() + " in place)");
    }
  }

  int run() override {
    log("update %s with %s", options_.cache.c_str(), options_.changes.c_str());
    ProgressBar bar(show_progress(), "tiles");
    const auto r = ingest::update_region(
        options_, [&bar](const ingest::PreprocessProgress& p) { bar.update(p.tiles_done, p.tiles_total); });
    bar.done();
    std::size_t changed = 0;
    for (const auto& type : r.changes.counts) {
      for (const std::size_t n : type) changed += n;
    }
    std::printf(
        "updated %s: %zu OSM objects changed, %zu features; %lld of %lld tiles re-rendered in %.3f s (apply %.3f s, "
        "read %.3f s, render+write %.3f s)\n",
        (options_.output.empty() ? options_.cache : options_.output).c_str(), changed, r.features_changed,
        static_cast<long long>(r.tiles_rendered), static_cast<long long>(r.tiles_total), r.total_seconds,
        r.apply_seconds, r.read_seconds, r.render_seconds);
    const auto& state = r.changes.replication;
    if (state.sequence.empty()) {
      std::printf("replication state: not known (change files do not carry it; --state records it)\n");
    } else {
      std::printf("replication state: sequence %s%s%s\n", state.sequence.c_str(),
                  state.timestamp.empty() ? "" : ", timestamp ", state.timestamp.c_str());
    }
    return kExitOk;
  }

 private:
  ingest::UpdateOptions options_;
};

}  // namespace

std::unique_ptr<Command> make_update_command() { return std::make_unique<UpdateCommand>(); }

}  // namespace seqloc::app
