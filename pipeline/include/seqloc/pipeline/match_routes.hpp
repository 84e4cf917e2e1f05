#pragma once
// The built-in matcher's volumes of observation routes, written as volume routes
// (docs/route-format.md): route.json, frames.csv with a volume column, the crops in region-grid
// metres and the ground truth, and volumes/NNNNNN.npy, float16 (H, W, N) log-probabilities. They
// can then be stored, shared, tempered and read by any tool; `seqloc localize` on them gives the
// poses it gives on the observation routes.

#include <cstddef>
#include <filesystem>
#include <functional>

#include "seqloc/pipeline/localize.hpp"

namespace seqloc::pipeline {

/// Writes `route`'s frames as a volume route in `dir` (created): each frame as localize prepares
/// it (stored_route_frames: the matcher's calibrated volume, normalized, in float16). Frames that
/// already carry a volume are written the same way. `on_frame` (optional) is called after each
/// frame. Throws DataError naming the file that cannot be read or written.
void write_volume_route(const io::Route& route, raster::CacheReader& cache, const LocalizeOptions& options,
                        const std::filesystem::path& dir, const std::function<void()>& on_frame = {});

}  // namespace seqloc::pipeline
