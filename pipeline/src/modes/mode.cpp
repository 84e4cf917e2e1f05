#include "factories.hpp"

namespace seqloc::pipeline {

void LocalizationMode::finish(io::RouteResult& result) { result.filter_seconds += filter_seconds_; }

double LocalizationMode::reported_etu_weight(double entropy) const {
  return filter::etu_weight(entropy, context_.options.filter.etu_reference_entropy);
}

std::size_t LocalizationMode::region_of(std::size_t i) const { return context_.regions ? (*context_.regions)[i] : 0; }

raster::CacheReader& LocalizationMode::cache_of(std::size_t i) const {
  return context_.catalog ? context_.catalog->cache(region_of(i)) : context_.cache;
}

const osm::RegionProjection& LocalizationMode::projection_of(std::size_t i) const {
  return context_.catalog ? context_.catalog->projection(region_of(i)) : projection_;
}

GridCrop LocalizationMode::crop_in_region_of(std::size_t s, std::size_t t) const {
  const auto& frames = context_.route.frames;
  const GridCrop own = frame_crop(frames[s], cache_of(s).grid(), projection_of(s));
  return region_of(s) == region_of(t) ? own : carry_crop(own, projection_of(s), projection_of(t));
}

std::unique_ptr<LocalizationMode> make_mode(io::Mode mode, const RouteContext& context) {
  switch (mode) {
    case io::Mode::single:
      return modes::make_single(context);
    case io::Mode::offline:
      return modes::make_offline(context);
    case io::Mode::online:
      return modes::make_sequential(context, /*online=*/true);
    case io::Mode::smooth:
      return modes::make_smooth(context);
    case io::Mode::seqloc:
      break;
  }
  return modes::make_sequential(context, /*online=*/false);
}

}  // namespace seqloc::pipeline
