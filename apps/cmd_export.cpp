// seqloc export: a layer of a region cache as a Cloud Optimized GeoTIFF, or the whole cache as a VRT.
#include <cstdio>
#include <filesystem>
#include <string>

#include "command.hpp"
#include "seqloc/core/error.hpp"
#include "seqloc/serve/geotiff.hpp"

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
    app.add_option("-o,--output", out_, "Output: .tif (Cloud Optimized GeoTIFF) or .vrt (the whole cache)")->required();
    add_overwrite_option(app, "output");
    add_progress_option(app);
  }

  void check() override {
    check_overwrite(out_);
    const std::string ext = out_.extension().string();
    vrt_ = ext == ".vrt";
    if (vrt_) {
      if (!bbox_.empty()) throw seqloc::UsageError("--bbox: a VRT covers the whole cache; export a .tif for a box");
      return;
    }
    if (ext != ".tif" && ext != ".tiff")
      throw seqloc::UsageError(out_.string() + ": the output must end in .tif or .vrt");
    const auto layer = serve::parse_layer(layer_);
    if (!layer) throw seqloc::UsageError("--layer '" + layer_ + "': classes, road_distance or road_prior");
    options_.layer = *layer;
    if (!bbox_.empty()) options_.bbox = parse_bbox(bbox_);
    options_.validate();  // --prior-sigma, --bbox: usage errors (exit 2)
  }

  int run() override {
    raster::CacheReader cache(cache_, 256);
    if (vrt_) {
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
  std::filesystem::path cache_, out_;
  std::string layer_ = "classes";
  std::string bbox_;
  serve::ExportOptions options_;
  bool vrt_ = false;  // check(): the output is a VRT of the whole cache
};

}  // namespace

std::unique_ptr<Command> make_export_command() { return std::make_unique<ExportCommand>(); }

}  // namespace seqloc::app
