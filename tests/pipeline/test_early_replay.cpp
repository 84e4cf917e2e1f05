// The early replay (FilterConfig::self_calibration_replay_frames): when self-calibration's power
// moves away from the one the route's first frames went in at, the localizer filters them again
// at the new power. Its belief is then the one a filter that knew the power from the start would
// have: checked against a localizer without self-calibration given the same frames raised to that
// power beforehand.

#include <cmath>
#include <random>
#include <vector>

#include <gtest/gtest.h>

#include "seqloc/ingest/preprocess.hpp"
#include "seqloc/osm/synthetic.hpp"
#include "seqloc/pipeline/sequential_localizer.hpp"
#include "support/test_support.hpp"

namespace seqloc::pipeline::early_replay_tests {
namespace {

constexpr double kLat0 = 47.5, kLon0 = 10.5;
constexpr int kBins = 32, kSide = 41, kCentre = 20, kFrames = 12;

// A road east through the map's centre, in a region centred there (its grid metres are the map's
// local metres).
std::filesystem::path road_cache(const std::filesystem::path& dir) {
  osm::SyntheticMap map(kLat0, kLon0);
  map.way({{-300, 0.25}, {300, 0.25}}, {{"highway", "track"}});
  map.write(dir / "map.osm.pbf");
  ingest::PreprocessOptions options;
  options.input = dir / "map.osm.pbf";
  options.output = dir / "road.gpkg";
  options.bbox = osm::GeoBox{kLon0 - 0.004, kLat0 - 0.002, kLon0 + 0.004, kLat0 + 0.002};
  ingest::preprocess_region(options);
  return options.output;
}

// Frame t: the vehicle at x = t m on the road heading east; its volume a blob of 3 cells around a
// point a few cells off the truth, in heading around east, every log-probability times 4 (a
// backbone four times too sharp), the crop centred on the truth.
struct Frame {
  filter::PreparedFrame prepared;
  GridCrop crop;
};
std::vector<Frame> sharp_frames() {
  std::mt19937 rng(3);
  std::uniform_int_distribution<int> off(-4, 4);
  std::vector<Frame> frames;
  for (int t = 0; t < kFrames; ++t) {
    const int du = off(rng), dv = off(rng);
    std::vector<float> values(static_cast<std::size_t>(kSide * kSide * kBins));
    for (int row = 0; row < kSide; ++row)
      for (int col = 0; col < kSide; ++col)
        for (int j = 0; j < kBins; ++j) {
          const double dj = std::min(std::abs(j - kBins / 4), kBins - std::abs(j - kBins / 4));
          const double r2 = (row - kCentre - dv) * (row - kCentre - dv) + (col - kCentre - du) * (col - kCentre - du);
          values[static_cast<std::size_t>((row * kSide + col) * kBins + j)] =
              static_cast<float>(4.0 * std::log(std::exp(-r2 / 18.0 - dj * dj / 2.0) + 1e-4));
        }
    frames.push_back({filter::prepare_frame({values.data(), filter::VolumeType::float32, filter::VolumeValues::log_prob,
                                             kSide, kSide, kBins, 0.5},
                                            kBins),
                      GridCrop{static_cast<double>(t), 0.25, 0}});
  }
  return frames;
}

filter::FilterConfig config() {
  filter::FilterConfig c;
  c.width = c.height = 128;
  c.headings = kBins;
  c.etu = false;  // ETU's weights read the frames as given, which the two localizers are not
  return c;
}

filter::Odometry odometry(int t) { return {t == 0 ? 0.0 : 1.0, 0, 0}; }

TEST(EarlyReplay, TheBeliefIsTheFiltersHadItKnownThePowerFromTheStart) {
  test::ScratchDir dir;
  raster::CacheReader cache(road_cache(dir.path()));
  const auto frames = sharp_frames();
  SequentialLocalizer live(cache, config(), /*online=*/false, 0.25);
  int replayed_at = -1;
  std::vector<SequentialLocalizer::Rewrite> rewritten;
  for (int t = 0; t < kFrames && replayed_at < 0; ++t) {
    (void)live.step(frames[static_cast<std::size_t>(t)].prepared, frames[static_cast<std::size_t>(t)].crop, odometry(t),
                    std::nullopt);
    rewritten = live.take_rewritten();
    if (!rewritten.empty()) replayed_at = t;
  }
  ASSERT_GT(replayed_at, 0) << "self-calibration moved the power away from 1 within " << kFrames << " frames";
  const double power = live.last_step().weighting.volume_power;
  EXPECT_LT(power, 0.5) << "frames four times too sharp are flattened";
  ASSERT_EQ(rewritten.size(), static_cast<std::size_t>(replayed_at)) << "every frame before the newest";
  for (std::size_t i = 0; i < rewritten.size(); ++i) {
    EXPECT_EQ(rewritten[i].index, i);
    EXPECT_EQ(rewritten[i].record.weighting.volume_power, power) << "frame " << i;
  }

  // The same frames raised to that power beforehand, through a filter that does not calibrate.
  filter::FilterConfig plain = config();
  plain.self_calibrate = false;
  SequentialLocalizer known(cache, plain, /*online=*/false, 0.25);
  for (int t = 0; t <= replayed_at; ++t) {
    const auto& f = frames[static_cast<std::size_t>(t)];
    (void)known.step(filter::temper_frame(f.prepared, power), f.crop, odometry(t), std::nullopt);
  }
  ASSERT_EQ(live.window().origin_u(), known.window().origin_u());
  ASSERT_EQ(live.window().origin_v(), known.window().origin_v());
  const filter::BeliefVolume& a = live.filter()->belief();
  const filter::BeliefVolume& b = known.filter()->belief();
  double worst = 0, peak = 0;
  for (int k = 0; k < a.headings(); ++k)
    for (int v = 0; v < a.height(); ++v)
      for (int u = 0; u < a.width(); ++u) {
        worst = std::max(worst, std::abs(static_cast<double>(a.prob(u, v, k)) - b.prob(u, v, k)));
        peak = std::max(peak, static_cast<double>(b.prob(u, v, k)));
      }
  EXPECT_LT(worst, 1e-4 * peak) << "largest difference " << worst << " against a peak of " << peak;
}

TEST(EarlyReplay, NoneWhenTurnedOff) {
  test::ScratchDir dir;
  raster::CacheReader cache(road_cache(dir.path()));
  const auto frames = sharp_frames();
  filter::FilterConfig c = config();
  c.self_calibration_replay_frames = 0;
  SequentialLocalizer live(cache, c, /*online=*/false, 0.25);
  double first_power = 0, last_power = 0;
  for (int t = 0; t < kFrames; ++t) {
    (void)live.step(frames[static_cast<std::size_t>(t)].prepared, frames[static_cast<std::size_t>(t)].crop, odometry(t),
                    std::nullopt);
    EXPECT_TRUE(live.take_rewritten().empty()) << "frame " << t;
    (t == 0 ? first_power : last_power) = live.last_step().weighting.volume_power;
  }
  EXPECT_EQ(first_power, 1.0);
  EXPECT_LT(last_power, 0.5) << "self-calibration still moves the power";
}

}  // namespace
}  // namespace seqloc::pipeline::early_replay_tests
