#include <cstdio>
#include <filesystem>
#include <string>
#include <vector>

#include <nlohmann/json.hpp>

#include "command.hpp"
#include "seqloc/raster/cache.hpp"

namespace seqloc::app {
namespace {

class CacheInfoCommand : public Command {
 public:
  void setup(CLI::App& app) override {
    app.add_option("cache", path_, "Region cache (GeoPackage)")->required();
    app.add_flag("--json", json_, "Print JSON instead of text");
  }

  int run() override {
    const auto metadata = raster::read_cache_metadata(path_);
    const auto rows = raster::metadata_rows(metadata);
    if (json_) {
      nlohmann::ordered_json out;
      out["path"] = path_.string();
      for (const auto& row : rows) {
        // The class table is JSON already, and numbers are JSON numbers (the rows hold each one
        // as a decimal that reads back to the same double, %.17g).
        if (row.kind != raster::MetadataRow::Kind::text && !row.value.empty()) {
          out[row.key] = nlohmann::json::parse(row.value);
        } else {
          out[row.key] = row.value;
        }
      }
      out["tiles_wide"] = metadata.grid.tiles_wide();
      out["tiles_high"] = metadata.grid.tiles_high();
      std::printf("%s\n", out.dump(2, ' ', false, nlohmann::json::error_handler_t::replace).c_str());
      return kExitOk;
    }
    std::printf("%-26s %s\n", "path", path_.c_str());
    for (const auto& row : rows) std::printf("%-26s %s\n", row.key.c_str(), row.value.c_str());
    std::printf("%-26s %lld x %lld tiles of 512 x 512 px (%.1f x %.1f km)\n", "extent",
                static_cast<long long>(metadata.grid.tiles_wide()), static_cast<long long>(metadata.grid.tiles_high()),
                (metadata.grid.max_x() - metadata.grid.min_x()) / 1000.0,
                (metadata.grid.max_y() - metadata.grid.min_y()) / 1000.0);
    return kExitOk;
  }

 private:
  std::filesystem::path path_;
  bool json_ = false;
};

class CacheMergeCommand : public Command, public WithOverwrite {
 public:
  void setup(CLI::App& app) override {
    app.add_option("output", out_, "Merged cache to write")->required();
    app.add_option("shards", shards_, "Every shard of one build (from preprocess --shard I/N)")->required();
    add_overwrite_option(app, "output");
  }

  void check() override { check_overwrite(out_); }

  int run() override {
    raster::merge_shards(shards_, out_);
    std::printf("merged %zu shards into %s\n", shards_.size(), out_.c_str());
    return kExitOk;
  }

 private:
  std::filesystem::path out_;
  std::vector<std::filesystem::path> shards_;
};

}  // namespace

std::unique_ptr<Command> make_cache_info_command() { return std::make_unique<CacheInfoCommand>(); }
std::unique_ptr<Command> make_cache_merge_command() { return std::make_unique<CacheMergeCommand>(); }

}  // namespace seqloc::app
