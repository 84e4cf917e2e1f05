// The built-in BEV matcher: the FFT correlation with quarter-turn reuse equals a direct sum over
// every pose; an observation rendered from the map at a known pose scores highest there; the
// observation PNG round-trips and every malformed one is one clear error.

#include <cmath>
#include <cstring>
#include <fstream>
#include <random>
#include <utility>

#include <gtest/gtest.h>

#include "seqloc/io/npy.hpp"
#include "seqloc/io/observation.hpp"
#include "seqloc/matcher/matcher.hpp"
#include "seqloc/raster/png_codec.hpp"
#include "support/test_support.hpp"

namespace seqloc::matcher {
namespace {

// A map of random blobs of a few classes in each channel.
std::vector<std::uint8_t> random_map(int side, std::uint32_t seed) {
  std::mt19937 rng(seed);
  std::vector<std::uint8_t> rgb(static_cast<std::size_t>(side * side * 3), 0);
  const int max_code[3] = {7, 10, 33};
  for (int c = 0; c < 3; ++c) {
    for (int blob = 0; blob < side * side / 40; ++blob) {
      const int code = 1 + static_cast<int>(rng() % static_cast<unsigned>(c == 2 ? 4 : max_code[c]));
      const int r0 = static_cast<int>(rng() % static_cast<unsigned>(side)),
                c0 = static_cast<int>(rng() % static_cast<unsigned>(side));
      const int radius = c == 2 ? 0 : 1 + static_cast<int>(rng() % 3u);
      for (int r = r0 - radius; r <= r0 + radius; ++r) {
        for (int cc = c0 - radius; cc <= c0 + radius; ++cc) {
          if (r >= 0 && r < side && cc >= 0 && cc < side)
            rgb[static_cast<std::size_t>((r * side + cc) * 3 + c)] = static_cast<std::uint8_t>(code);
        }
      }
    }
  }
  return rgb;
}

TEST(Matcher, TheSameVolumeForAnyNumberOfThreads) {
  // The headings are shared among the threads of the pool; each is scored alike wherever it runs.
  matcher::MatcherConfig config;
  config.size = 12;
  config.headings = 80;
  const int t = 7;
  io::Observation obs(t);
  std::mt19937 rng(9);
  for (std::size_t i = 0; i < obs.cells(); ++i) {
    obs.visible[i] = rng() % 4 != 0;
    obs.classes[3 * i] = static_cast<std::uint8_t>(rng() % 3);
    obs.classes[3 * i + 1] = rng() % 5 == 0 ? 8 : 0;
  }
  config.threads = 1;
  const auto map = random_map(matcher::BevMatcher(config).map_side(t), 21u);
  const auto one = matcher::BevMatcher(config).match(obs, map);
  for (const int threads : {2, 3, 8}) {
    config.threads = threads;
    const auto many = matcher::BevMatcher(config).match(obs, map);
    ASSERT_EQ(one.size(), many.size());
    ASSERT_EQ(std::memcmp(one.data(), many.data(), one.size() * sizeof(float)), 0) << threads << " threads";
  }
}

TEST(Matcher, FftCorrelationEqualsDirectSum) {
  // FFT sizes 16, 18 and 27 (odd), and 80 headings (batches of 16 headings written to the volume,
  // across two threads). Without trees, one channel shows a single code (all background), which
  // the matcher folds into the template of the whole visible disc.
  struct Case {
    int size, headings;
    bool trees;
  };
  for (const auto& [size, headings, trees] :
       {Case{10, 8, true}, Case{10, 16, false}, Case{20, 16, true}, Case{12, 80, true}, Case{12, 80, false}}) {
    matcher::MatcherConfig config;
    config.size = size;
    config.headings = headings;
    config.temperature = 3.0;
    config.threads = 2;
    const matcher::BevMatcher matcher(config);
    const int t = 7, side = matcher.map_side(t);
    const auto map = random_map(side, 11u + static_cast<std::uint32_t>(headings + size));
    io::Observation obs(t);
    std::mt19937 rng(5);
    for (std::size_t i = 0; i < obs.cells(); ++i) {
      obs.visible[i] = rng() % 4 != 0;
      obs.classes[3 * i] = static_cast<std::uint8_t>(rng() % 3);  // background, building, parking
      obs.classes[3 * i + 1] = rng() % 5 == 0 ? 8 : 0;            // road
      obs.classes[3 * i + 2] = trees && rng() % 9 == 0 ? 1 : 0;   // tree
    }
    const auto volume = matcher.match(obs, map);
    ASSERT_EQ(volume.size(), static_cast<std::size_t>(config.size * config.size * headings));

    double worst = 0, largest = 0;
    for (int k = 0; k < headings; ++k) {
      std::vector<double> reference(static_cast<std::size_t>(config.size * config.size), 0.0);
      for (const auto& [channel, code] : matcher::BevMatcher::observed_codes(obs)) {
        const auto tmpl = matcher.rotated_template(obs, channel, code, k * 360.0 / headings);
        const auto term = matcher.map_term(channel, code, map, side);
        for (int v = 0; v < config.size; ++v) {
          for (int u = 0; u < config.size; ++u) {
            double sum = 0;
            for (int r = 0; r < t; ++r) {
              for (int c = 0; c < t; ++c) {
                sum +=
                    tmpl[static_cast<std::size_t>(r * t + c)] * term[static_cast<std::size_t>((v + r) * side + u + c)];
              }
            }
            reference[static_cast<std::size_t>(v * config.size + u)] += sum / config.temperature;
          }
        }
      }
      for (int v = 0; v < config.size; ++v) {
        for (int u = 0; u < config.size; ++u) {
          const double fast = volume[static_cast<std::size_t>((v * config.size + u) * headings + k)];
          const double ref = reference[static_cast<std::size_t>(v * config.size + u)];
          worst = std::max(worst, std::abs(fast - ref));
          largest = std::max(largest, std::abs(ref));
        }
      }
    }
    // float32 FFTs of size 16-27: errors of a few 1e-6 of the largest score.
    EXPECT_LT(worst, 1e-4 * largest) << size << " cells, " << headings << " headings: worst " << worst << " of "
                                     << largest;
    EXPECT_GT(largest, 1.0);
  }
}

// Renders what a camera at region cell (v0 + 0.5, u0 + 0.5) of the map crop... : the observation
// at volume cell (v, u) and grid heading `heading_deg`, by nearest neighbour, every cell visible.
io::Observation render(const std::vector<std::uint8_t>& map, int side, int size, int t, int v, int u,
                       double heading_deg) {
  io::Observation obs(t);
  const double centre = (t - 1) / 2.0;
  // Volume cell (v, u) is map cell (v + centre, u + centre) of the crop.
  const double th = heading_deg * M_PI / 180.0;
  for (int r = 0; r < t; ++r) {
    for (int c = 0; c < t; ++c) {
      const double f = centre - r, rt = c - centre;  // forward, right (cells)
      const double e = f * std::sin(th) + rt * std::cos(th), n = f * std::cos(th) - rt * std::sin(th);
      const auto mr = static_cast<int>(std::lround(v + centre - n)), mc = static_cast<int>(std::lround(u + centre + e));
      const auto i = static_cast<std::size_t>(r * t + c);
      obs.visible[i] = 1;
      for (int ch = 0; ch < 3; ++ch)
        obs.classes[3 * i + static_cast<std::size_t>(ch)] = map[static_cast<std::size_t>((mr * side + mc) * 3 + ch)];
    }
  }
  (void)size;
  return obs;
}

TEST(Matcher, ObservationRenderedAtAPoseScoresHighestThere) {
  matcher::MatcherConfig config;
  config.size = 32;
  config.headings = 64;
  config.threads = 2;
  const matcher::BevMatcher matcher(config);
  const int t = 25, side = matcher.map_side(t);
  const auto map = random_map(side, 3);
  struct Case {
    int v, u, bin;
  };
  for (const Case& truth : {Case{10, 20, 0}, Case{16, 16, 16}, Case{5, 27, 37}, Case{22, 9, 7}}) {
    const double heading = truth.bin * 360.0 / config.headings;
    const auto obs = render(map, side, config.size, t, truth.v, truth.u, heading);
    const auto volume = matcher.match(obs, map);
    const auto best = std::max_element(volume.begin(), volume.end()) - volume.begin();
    const auto cell = best / config.headings;
    EXPECT_EQ(cell / config.size, truth.v) << "bin " << truth.bin;
    EXPECT_EQ(cell % config.size, truth.u) << "bin " << truth.bin;
    EXPECT_EQ(best % config.headings, truth.bin);
  }
}

TEST(Matcher, RejectsBadConfigurationsAndSizes) {
  matcher::MatcherConfig config;
  config.headings = 30;
  EXPECT_THROW(matcher::BevMatcher{config}, UsageError);
  config = {};
  config.size = 9;
  EXPECT_THROW(matcher::BevMatcher{config}, UsageError);
  config = {};
  config.miss_rate = 0.95;
  EXPECT_THROW(matcher::BevMatcher{config}, UsageError);
  config = {};
  config.size = 8;
  const matcher::BevMatcher matcher(config);
  const io::Observation obs(5);
  EXPECT_THROW((void)matcher.match(obs, std::vector<std::uint8_t>(10 * 10 * 3)), UsageError);
}

TEST(Observation, RoundTripsThroughPng) {
  test::ScratchDir dir;
  io::Observation obs(9);
  for (std::size_t i = 0; i < obs.cells(); ++i) {
    obs.classes[3 * i] = static_cast<std::uint8_t>(i % 8);
    obs.classes[3 * i + 1] = static_cast<std::uint8_t>(i % 11);
    obs.classes[3 * i + 2] = static_cast<std::uint8_t>(i % 34);
    obs.visible[i] = i % 3 != 0;
  }
  io::write_observation(dir.path() / "obs.png", obs);
  const auto back = io::read_observation(dir.path() / "obs.png");
  EXPECT_EQ(back.size, 9);
  EXPECT_EQ(back.classes, obs.classes);
  EXPECT_EQ(back.visible, obs.visible);
  EXPECT_FALSE(std::filesystem::exists(dir.path() / "obs.png.tmp"));
}

void write_bytes(const std::filesystem::path& path, const std::vector<std::uint8_t>& bytes) {
  std::ofstream(path, std::ios::binary)
      .write(reinterpret_cast<const char*>(bytes.data()), static_cast<std::streamsize>(bytes.size()));
}

void expect_error(const std::filesystem::path& path, const std::string& fragment) {
  try {
    (void)io::read_observation(path);
    ADD_FAILURE() << "no error for " << path;
  } catch (const DataError& e) {
    EXPECT_NE(std::string(e.what()).find(path.string()), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find(fragment), std::string::npos) << e.what();
  }
}

TEST(Observation, MalformedFilesAreOneClearError) {
  test::ScratchDir dir;
  expect_error(dir.path() / "missing.png", "cannot open");
  write_bytes(dir.path() / "text.png", {'h', 'e', 'l', 'l', 'o'});
  expect_error(dir.path() / "text.png", "not a PNG");
  write_bytes(dir.path() / "rgb.png", raster::encode_png_rgb8(std::vector<std::uint8_t>(9 * 9 * 3), 9, 9));
  expect_error(dir.path() / "rgb.png", "8-bit RGBA");
  write_bytes(dir.path() / "even.png", raster::encode_png_rgba8(std::vector<std::uint8_t>(8 * 8 * 4), 8, 8));
  expect_error(dir.path() / "even.png", "odd side");
  write_bytes(dir.path() / "wide.png", raster::encode_png_rgba8(std::vector<std::uint8_t>(9 * 7 * 4), 9, 7));
  expect_error(dir.path() / "wide.png", "9 x 7");
  std::vector<std::uint8_t> rgba(9 * 9 * 4, 0);
  rgba[(2 * 9 + 3) * 4 + 1] = 11;  // ways has codes 0..10
  write_bytes(dir.path() / "code.png", raster::encode_png_rgba8(rgba, 9, 9));
  expect_error(dir.path() / "code.png", "row 2, column 3) has ways code 11");
  write_bytes(dir.path() / "huge.png", raster::encode_png_rgba8(std::vector<std::uint8_t>(601 * 3 * 4), 601, 3));
  expect_error(dir.path() / "huge.png", "largest accepted");
  auto truncated = raster::encode_png_rgba8(std::vector<std::uint8_t>(9 * 9 * 4, 7), 9, 9);
  truncated.resize(truncated.size() / 2);
  write_bytes(dir.path() / "truncated.png", truncated);
  expect_error(dir.path() / "truncated.png", "truncated.png");
}

}  // namespace
}  // namespace seqloc::matcher
