// offline: frame t's pose from the frames within offline_half_window of it, each placed by its
// own crop and aligned to t by the relative motion, their log-likelihoods summed
// (filter::OfflineAggregator, which keeps each frame's placement while it stays in range).
#include <algorithm>

#include "factories.hpp"
#include "seqloc/filter/offline.hpp"
#include "seqloc/pipeline/region_window.hpp"

namespace seqloc::pipeline::modes {
namespace {

class OfflineMode final : public LocalizationMode {
 public:
  explicit OfflineMode(const RouteContext& context)
      : LocalizationMode(context),
        window_(context.cache, context.options.filter.width, context.options.filter.height),
        aggregator_(context.options.filter) {}

  [[nodiscard]] bool lookahead() const override { return false; }

  FrameEstimate estimate(std::size_t i, const GridCrop& crop, FramePrefetcher& frames) override {
    const Route& route = context_.route;
    const filter::PreparedFrame& frame = frames.get(i);
    const int half = context_.options.offline_half_window;
    const std::size_t k = half < 0 ? route.frames.size() : static_cast<std::size_t>(half);
    const std::size_t s0 = i > k ? i - k : 0, s1 = std::min(route.frames.size() - 1, i + k);
    frames.release_before(s0);
    // A window centred on frame t's crop.
    window_.centre_on(crop.x, crop.y);
    std::vector<filter::OfflineFrame> range;
    for (std::size_t s = s0; s <= s1; ++s) {
      const GridCrop c = frame_crop(route.frames[s], context_.cache.grid(), context_.cache.metadata().projection());
      range.push_back({&frames.get(s), window_.crop_pose(c), route.frames[s].odometry, static_cast<std::int64_t>(s)});
    }
    const auto t0 = Clock::now();
    const filter::Pose p = aggregator_.pose_at(range, i - s0, -1);
    filter_seconds_ += seconds_since(t0);
    FrameEstimate e;
    e.x_m = window_.x_of(p.u);
    e.y_m = window_.y_of(p.v);
    e.grid_heading_deg = p.heading_deg;
    e.entropy = frame.entropy;
    e.etu_weight = reported_etu_weight(frame.entropy);
    return e;
  }

 private:
  RegionWindow window_;
  filter::OfflineAggregator aggregator_;
};

}  // namespace

std::unique_ptr<LocalizationMode> make_offline(const RouteContext& context) {
  return std::make_unique<OfflineMode>(context);
}

}  // namespace seqloc::pipeline::modes
