// seqloc export: a layer of a region cache as a Cloud Optimized GeoTIFF, as a PMTiles or MBTiles
// archive of its Web Mercator tiles (a web map without a server), or the whole cache as a VRT.
#include <charconv>
#include <cstdio>
#include <filesystem>
#include <string>

#include "command.hpp"
#include "seqloc/core/error.hpp"
#include "seqloc/serve/geotiff.hpp"
#include "seqloc/serve/tile_archive.hpp"

namespace seqloc::app {
namespace {

class ExportCommand : public Command, public WithOverwrite, public WithProgress {
 public:
  void setup(CLI::App& app) override {
    app.add_option("cache", cache_, "Region cache (GeoPackage)")->required()->check(CLI::ExistingFile);
    app.add_option("--layer", layer_, "classes, road_distance or road_prior")->capture_default_str();
    app.add_option("--bbox", bbox_, "lon0,lat0,lon1,lat1 to export (default: the whole region)");
    app.add_option("--prior-sigma", options_.layer_options.prior_sigma_m, "Sigma of road_prior, metres")
        ->capture_default_str();
    app.add_flag("--float", options_.float32,
                 "road_distance as Float32 metres (default: UInt16 centimetres, scale 0.01, unit m)");
    app.add_option("-o,--output", out_,
                   "Output: .tif (Cloud Optimized GeoTIFF), .pmtiles or .mbtiles (Web Mercator tiles), or .vrt "
                   "(the whole cache)")
        ->required();
    app.add_option("--format", format_, "cog, pmtiles, mbtiles or vrt (default: from the output's extension)");
    app.add_option("--zoom", zoom_,
                   "MIN-MAX: the zooms of a PMTiles or MBTiles archive (default: those the server's XYZ tiles have)");
    app.add_option("--style", style_,
                   "Tiles of a PMTiles or MBTiles archive: color (pictures, as web maps show them) or data (the "
                   "values as PNG)")
        ->capture_default_str();
    app.add_option("--threads", threads_, "Tiles warped side by side, PMTiles and MBTiles (0: all cores)")
        ->capture_default_str()
        ->check(CLI::Range(0, 1024));
    app.add_option("--root-bytes", archive_.pmtiles_root_bytes,
                   "PMTiles: the budget of the header and root directory, read first by every client (16 KiB at "
                   "most, the specification's limit)")
        ->capture_default_str()
        ->check(CLI::Range(256, 16384));
    app.add_option("--leaf-entries", archive_.pmtiles_leaf_entries,
                   "PMTiles: entries of a leaf directory when the root alone would pass its budget")
        ->capture_default_str()
        ->check(CLI::Range(1, 1 << 20));
    add_overwrite_option(app, "output");
    add_progress_option(app);
  }

  void check() override {
    check_overwrite(out_);
    const std::string ext = out_.extension().string();
    if (format_.empty()) {
      if (ext == ".tif" || ext == ".tiff") format_ = "cog";
      if (ext == ".pmtiles" || ext == ".mbtiles" || ext == ".vrt") format_ = ext.substr(1);
      if (format_.empty()) {
        throw seqloc::UsageError(out_.string() +
                                 ": the output must end in .tif, .pmtiles, .mbtiles or .vrt (or give --format)");
      }
    }
    if (format_ != "cog" && format_ != "pmtiles" && format_ != "mbtiles" && format_ != "vrt") {
      throw seqloc::UsageError("--format '" + format_ + "': cog, pmtiles, mbtiles or vrt");
    }
    const bool archive = format_ == "pmtiles" || format_ == "mbtiles";
    if (!archive && (!zoom_.empty() || style_ != "color")) {
      throw seqloc::UsageError("--zoom and --style are for PMTiles and MBTiles archives");
    }
    if (format_ == "vrt") {
      if (!bbox_.empty()) throw seqloc::UsageError("--bbox: a VRT covers the whole cache; export a .tif for a box");
      return;
    }
    const auto layer = serve::parse_layer(layer_);
    if (!layer) throw seqloc::UsageError("--layer '" + layer_ + "': classes, road_distance or road_prior");
    options_.layer = *layer;
    if (archive) {
      check_archive();
      return;
    }
    if (!bbox_.empty()) options_.bbox = parse_bbox(bbox_);
    options_.validate();  // --prior-sigma, --bbox: usage errors (exit 2)
  }

  void check_archive() {
    if (!bbox_.empty() || options_.float32) {
      throw seqloc::UsageError("--bbox and --float are for GeoTIFF exports; an archive covers the region");
    }
    if (style_ != "color" && style_ != "data") throw seqloc::UsageError("--style '" + style_ + "': color or data");
    archive_.layer = options_.layer;
    archive_.styled = style_ == "color";
    archive_.threads = threads_ == 0 ? default_threads() : threads_;
    archive_.layer_options = options_.layer_options;
    if (!zoom_.empty()) {
      const auto dash = zoom_.find('-');
      const auto number = [this](std::string_view text) {
        int value = -1;
        const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), value);
        if (error != std::errc() || end != text.data() + text.size() || value < 0 || value > 26) {
          throw seqloc::UsageError("--zoom '" + zoom_ + "': MIN-MAX or Z, zooms 0 to 26");
        }
        return value;
      };
      archive_.min_zoom = number(std::string_view(zoom_).substr(0, dash));
      archive_.max_zoom =
          dash == std::string::npos ? *archive_.min_zoom : number(std::string_view(zoom_).substr(dash + 1));
      if (*archive_.min_zoom > *archive_.max_zoom) throw seqloc::UsageError("--zoom '" + zoom_ + "': MIN above MAX");
    }
    try {
      archive_.layer_options.validate();
    } catch (const std::exception& e) {
      throw seqloc::UsageError(e.what());
    }
  }

  int run() override {
    raster::CacheReader cache(cache_, 256);
    if (format_ == "pmtiles" || format_ == "mbtiles") return run_archive(cache);
    if (format_ == "vrt") {
      serve::write_region_vrt(cache, out_);
      std::printf("wrote %s (classes: bands 1-3, road distance in metres: band 4)\n", out_.c_str());
      return kExitOk;
    }
    ProgressBar bar(show_progress(), "export");
    options_.progress = [&](long long done, long long total) { bar.update(done, total); };
    serve::export_cog(cache, options_, out_);
    bar.done();
    std::printf("wrote %s (%s, Cloud Optimized GeoTIFF)\n", out_.c_str(), layer_.c_str());
    return kExitOk;
  }

 private:
  int run_archive(raster::CacheReader& cache) {
    ProgressBar bar(show_progress(), "export");
    archive_.progress = [&](long long done, long long total) { bar.update(done, total); };
    const auto format = format_ == "pmtiles" ? serve::ArchiveFormat::pmtiles : serve::ArchiveFormat::mbtiles;
    const serve::ArchiveSummary s = serve::export_tile_archive(cache, archive_, format, out_);
    bar.done();
    std::printf("wrote %s (%s, %s, style %s): zooms %d-%d, %lld tiles (%lld stored), %.1f MB\n", out_.c_str(),
                format_ == "pmtiles" ? "PMTiles v3" : "MBTiles 1.3", layer_.c_str(), style_.c_str(), s.min_zoom,
                s.max_zoom, s.tiles, s.unique_tiles, static_cast<double>(s.file_bytes) / 1e6);
    return kExitOk;
  }

  std::filesystem::path cache_, out_;
  std::string layer_ = "classes";
  std::string bbox_, format_, zoom_, style_ = "color";
  int threads_ = 0;
  serve::ExportOptions options_;
  serve::ArchiveOptions archive_;
};

}  // namespace

std::unique_ptr<Command> make_export_command() { return std::make_unique<ExportCommand>(); }

}  // namespace seqloc::app
