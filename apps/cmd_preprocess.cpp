#include <malloc.h>

#include <cstdio>
#include <iomanip>
#include <sstream>
#include <string>

#include <filesystem>
#include <stdexcept>

#include "command.hpp"
#include "seqloc/core/files.hpp"
#include "seqloc/ingest/preprocess.hpp"
#include "seqloc/io/preprocess_report.hpp"

namespace seqloc::app {

osm::GeoBox parse_bbox(const std::string& text) {
  const auto v = parse_numbers<double>(text, ',', 4);
  if (!v) throw seqloc::UsageError("--bbox '" + text + "': expected lon0,lat0,lon1,lat1 (decimal degrees)");
  return {(*v)[0], (*v)[1], (*v)[2], (*v)[3]};
}

namespace {

class PreprocessCommand : public Command, public WithProgress {
 public:
  void setup(CLI::App& app) override {
    app.add_option("input", options_.input, "OSM input: .osm.pbf, .osm, .osm.gz or .osm.bz2")->required();
    app.add_option("-o,--output", options_.output, "Region cache to write (GeoPackage, e.g. region.gpkg)")
        ->required();
    app.add_option("--bbox", bbox_, "Region lon0,lat0,lon1,lat1 (default: the file header's bbox, else the data's)");
    app.add_option("--max-distance", options_.max_distance_m, "Road-distance clamp in metres")
        ->capture_default_str()
        ->check(CLI::Range(0.01, ingest::kMaxClampM));
    app.add_option("--corridor", options_.corridor_m,
                   "Store only tiles with a cell nearer than this many metres to a road (0: every tile; at most "
                   "--max-distance); readers take a left-out tile as background and the clamp")
        ->capture_default_str()
        ->check(CLI::Range(0.0, ingest::kMaxClampM));
    app.add_option("--threads", options_.threads, "Worker threads (0: all cores)")->capture_default_str()->check(
        CLI::NonNegativeNumber);
    app.add_option("--shard", shard_,
                   "Build only shard I of N (I/N, 0-based), e.g. --shard $SLURM_ARRAY_TASK_ID/$SLURM_ARRAY_TASK_COUNT; "
                   "combine the shards with `seqloc cache merge`");
    add_progress_option(app);
    app.add_flag("--overwrite", options_.overwrite, "Replace an existing cache");
    app.add_option("--report", report_path_, "Also write the run's figures (tiles, timings per stage) as JSON");
    app.footer(
        "The cache is written to OUTPUT.partial and renamed when complete; an interrupted build resumes from the\n"
        "partial file when rerun with the same input and options. See docs/cache-format.md.");
  }

  void check() override {
    if (!bbox_.empty()) options_.bbox = parse_bbox(bbox_);
    if (!shard_.empty()) {
      const auto v = parse_numbers<int>(shard_, '/', 2);
      if (!v) throw seqloc::UsageError("--shard '" + shard_ + "': expected I/N, e.g. 0/4");
      options_.shard_index = (*v)[0];
      options_.shard_count = (*v)[1];
    }
    options_.validate();
  }

  int run() override {
    // Reading leaves the heap long and fragmented; rendering should not carry it. Buffers of 1 MB
    // and more (the features' larger vectors) come from mmap and go back to the system when freed
    // (glibc would otherwise raise that threshold as big blocks are freed and serve later ones
    // from the fragmented heap). And every thread allocates from the one main heap, which
    // malloc_trim releases whole: the PBF decoder threads would otherwise leave an arena of their
    // own, which trimming does not shrink and which rendering's threads then take over
    // (10x andorra when rendering starts: 93 MB resident with neither, 63 MB with the threshold,
    // 46 MB with both, as at 1x).
    ::mallopt(M_MMAP_THRESHOLD, 1 << 20);
    ::mallopt(M_ARENA_MAX, 1);
    log("preprocess %s -> %s", options_.input.c_str(), options_.output.c_str());
    ProgressBar bar(show_progress(), "tiles");
    const auto report = ingest::preprocess_region(
        options_, [&bar](const ingest::PreprocessProgress& p) { bar.update(p.tiles_done, p.tiles_total); });
    bar.done();
    std::ostringstream out;
    out.precision(3);
    out << std::fixed << "wrote " << options_.output.string() << ": " << report.tiles_wide << " x " << report.tiles_high
        << " tiles (" << report.tiles_total << " in this shard, " << report.tiles_written << " rendered, "
        << report.tiles_resumed << " resumed";
    if (options_.corridor_m > 0) {
      out << ", " << report.tiles_skipped << " without classes beyond the " << options_.corridor_m << " m corridor";
    }
    out << "), " << report.roads << " roads, " << report.areas << " areas, "
        << report.lines << " lines, " << report.nodes << " nodes in " << report.total_seconds << " s (read "
        << report.read_seconds << " s, render+write " << report.render_seconds << " s); scale error at the grid's "
        << "edge " << std::defaultfloat << std::setprecision(2) << report.scale_error * 100 << " %\n";
    if (report.ways_missing_nodes > 0) {
      out << "note: " << report.ways_missing_nodes << " ways referenced nodes missing from the input (drawn with the "
          << "nodes present)\n";
    }
    if (report.multipolygon_open_chains > 0) {
      out << "note: " << report.multipolygon_open_chains << " multipolygon member chains did not close (members "
          << "missing from the input); their relations are drawn from the rings that close\n";
    }
    std::fputs(out.str().c_str(), stdout);
    if (!report_path_.empty()) core::write_file(report_path_, io::preprocess_report_json(report));
    return kExitOk;
  }

 private:
  ingest::PreprocessOptions options_;
  std::string bbox_;
  std::string shard_;
  std::string report_path_;
};

}  // namespace

std::unique_ptr<Command> make_preprocess_command() { return std::make_unique<PreprocessCommand>(); }

}  // namespace seqloc::app
