// offline: frame t's pose from the frames within offline_half_window of it, each placed by its
// own crop and aligned to t by the relative motion, their log-likelihoods summed
// (offline::OfflineAggregator, which keeps each frame's placement while it stays in range). On a
// route that crosses regions, frame t's window is in t's region and the others' crops are carried
// into it.
#include <algorithm>
#include <optional>

#include "factories.hpp"
#include "seqloc/offline/offline.hpp"
#include "seqloc/pipeline/region_window.hpp"

namespace seqloc::pipeline::modes {
namespace {

class OfflineMode final : public LocalizationMode {
 public:
  explicit OfflineMode(const RouteContext& context) : LocalizationMode(context), aggregator_(context.options.filter) {}

  [[nodiscard]] bool lookahead() const override { return false; }

  FrameEstimate estimate(std::size_t i, const GridCrop& crop, FramePrefetcher& frames) override {
    const io::Route& route = context_.route;
    const filter::PreparedFrame& frame = frames.get(i);
    const int half = context_.options.offline_half_window;
    const std::size_t k = half < 0 ? route.frames.size() : static_cast<std::size_t>(half);
    const std::size_t s0 = i > k ? i - k : 0, s1 = std::min(route.frames.size() - 1, i + k);
    frames.release_before(s0);
    // A window centred on frame t's crop, in t's region.
    RegionWindow& window = window_in(cache_of(i));
    window.centre_on(crop.x, crop.y);
    std::vector<offline::OfflineFrame> range;
    for (std::size_t s = s0; s <= s1; ++s) {
      const GridCrop c = crop_in_region_of(s, i);
      range.push_back({&frames.get(s), window.crop_pose(c), route.frames[s].odometry, static_cast<std::int64_t>(s)});
    }
    const auto t0 = Clock::now();
    const filter::Pose p = aggregator_.pose_at(range, i - s0, -1);
    filter_seconds_ += seconds_since(t0);
    FrameEstimate e;
    e.x_m = window.x_of(p.u);
    e.y_m = window.y_of(p.v);
    e.grid_heading_deg = p.heading_deg;
    e.entropy = frame.entropy;
    e.etu_weight = reported_etu_weight(frame.entropy);
    return e;
  }

 private:
  RegionWindow& window_in(raster::CacheReader& cache) {
    if (!window_ || &window_->cache() != &cache) {
      window_.emplace(cache, context_.options.filter.width, context_.options.filter.height);
    }
    return *window_;
  }

  std::optional<RegionWindow> window_;  ///< in the current frame's region
  offline::OfflineAggregator aggregator_;
};

}  // namespace

std::unique_ptr<LocalizationMode> make_offline(const RouteContext& context) {
  return std::make_unique<OfflineMode>(context);
}

}  // namespace seqloc::pipeline::modes
