// single: each frame's own argmax, placed by its crop; no memory of earlier frames.
#include "factories.hpp"

namespace seqloc::pipeline::modes {
namespace {

class SingleMode final : public LocalizationMode {
 public:
  explicit SingleMode(const RouteContext& context) : LocalizationMode(context) {}

  FrameEstimate estimate(std::size_t i, const GridCrop& crop, FramePrefetcher& frames) override {
    const filter::PreparedFrame& frame = frames.get(i);
    // The volume's own argmax, relative to its crop centre.
    const filter::Pose p = filter::single_frame_pose(frame, {0, 0, crop.rotation_deg});
    FrameEstimate e;
    e.x_m = crop.x + p.u * raster::kCellM;
    e.y_m = crop.y - p.v * raster::kCellM;
    e.grid_heading_deg = p.heading_deg;
    e.entropy = frame.entropy;
    e.etu_weight = reported_etu_weight(frame.entropy);
    if (context_.inspect) context_.inspect({i, &frame, crop, nullptr});
    frames.release(i);
    return e;
  }
};

}  // namespace

std::unique_ptr<LocalizationMode> make_single(const RouteContext& context) {
  return std::make_unique<SingleMode>(context);
}

}  // namespace seqloc::pipeline::modes
