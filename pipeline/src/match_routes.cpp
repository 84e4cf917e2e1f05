#include "seqloc/pipeline/match_routes.hpp"

#include <algorithm>
#include <cstdint>
#include <cstdio>
#include <vector>

#include "seqloc/core/files.hpp"
#include "seqloc/io/npy.hpp"
#include "seqloc/io/run_folder.hpp"

namespace seqloc::pipeline {

void write_volume_route(const io::Route& route, raster::CacheReader& cache, const LocalizeOptions& options,
                        const std::filesystem::path& dir, const std::function<void()>& on_frame) {
  const FrameSource source = stored_route_frames(route, cache, options);
  const auto& projection = cache.metadata().projection();
  std::filesystem::create_directories(dir / "volumes");
  io::Route out = route;
  out.dir = dir;
  out.volume_kind = filter::VolumeValues::log_prob;
  out.layout = io::VolumeLayout::hwn;
  out.layout_declared = true;
  std::vector<std::uint16_t> halves;
  for (std::size_t i = 0; i < route.frames.size(); ++i) {
    const auto frame = source(i);
    const int H = frame->height, W = frame->width, N = frame->bins;
    // The values are float16 already (the frame store's rounding): back to half bits exactly.
    const std::vector<float> values = hwn_values(*frame);
    halves.resize(values.size());
    filter::floats_to_halves(values, halves);
    char name[32];
    std::snprintf(name, sizeof name, "%06zu.npy", i);
    const std::filesystem::path path = dir / "volumes" / name;
    core::write_file(path, io::encode_npy_float16(H, W, N, halves.data()));
    if (i == 0) out.cell_m = frame->cell_m;
    if (frame->cell_m != out.cell_m) {
      throw DataError(route.dir.string() + "/frames.csv:" + std::to_string(route.frames[i].line) +
                      ": the frame's cells differ in size from the first frame's; a route has one cell size");
    }
    io::RouteFrame& f = out.frames[i];
    if (!f.observation.empty()) {
      // The crop the matcher's volume lies on: the observation's, snapped to the grid as localize
      // places it, north-up in the grid.
      const GridCrop crop = frame_crop(route.frames[i], cache.grid(), projection);
      f.crop_grid = osm::GridPoint{crop.x, crop.y};
      f.crop_geo.reset();
    }
    f.volume = path;
    f.observation.clear();
    if (on_frame) on_frame();
  }
  io::write_route(out, dir);
}

}  // namespace seqloc::pipeline
