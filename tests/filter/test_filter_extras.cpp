// The baselines (single, offline), heading-bin resampling, window moves, and the additions beyond
// the paper (sub-bin heading, motion noise, GPS prior, relocalization flag).

#include <cmath>
#include <random>

#include <gtest/gtest.h>

#include "seqloc/filter/device_math.hpp"
#include "seqloc/filter/resample.hpp"
#include "seqloc/filter/seqloc_filter.hpp"
#include "seqloc/offline/offline.hpp"

namespace seqloc::filter {
namespace {

using offline::offline_poses;
using offline::OfflineAggregator;
using offline::OfflineFrame;

FilterConfig config(int w, int h, int r) {
  FilterConfig c;
  c.width = w;
  c.height = h;
  c.headings = r;
  return c;
}

// Log-probabilities of a Gaussian bump at volume cell (v, u) and bin j (sharp, but smooth enough
// to interpolate).
std::vector<float> bump(int h, int w, int n, double v0, double u0, double j0, double sigma = 1.0,
                        double sigma_bins = 0.7) {
  std::vector<float> out(static_cast<std::size_t>(h * w * n));
  for (int v = 0; v < h; ++v)
    for (int u = 0; u < w; ++u)
      for (int j = 0; j < n; ++j) {
        double dj = std::fmod(std::abs(j - j0), n);
        dj = std::min(dj, n - dj);
        out[static_cast<std::size_t>((v * w + u) * n + j)] = static_cast<float>(
            -((v - v0) * (v - v0) + (u - u0) * (u - u0)) / (2 * sigma * sigma) - dj * dj / (2 * sigma_bins * sigma_bins));
      }
  return out;
}

FrameVolume view(const std::vector<float>& v, int h, int w, int n) {
  return FrameVolume{v.data(), VolumeType::float32, VolumeValues::log_prob, h, w, n, 0.5};
}

TEST(Odometry, ComposeAndInvert) {
  // A quarter circle driven as four 22.5-degree turns returns to a pose 90 degrees left.
  const Odometry m = compose({{5, 0, 90}, {5, 0, 0}});
  EXPECT_NEAR(m.forward_m, 5, 1e-12);
  EXPECT_NEAR(m.left_m, 5, 1e-12);
  EXPECT_NEAR(m.yaw_deg, 90, 1e-12);
  const Odometry back = compose({m, invert(m)});
  EXPECT_NEAR(back.forward_m, 0, 1e-12);
  EXPECT_NEAR(back.left_m, 0, 1e-12);
  EXPECT_NEAR(back.yaw_deg, 0, 1e-12);
}

TEST(Baselines, SingleFramePoseHandlesRotatedCrops) {
  const auto vol = bump(9, 9, 16, 0, 4, 0);  // north edge centre, heading 0 in the crop
  const auto frame = prepare_frame(view(vol, 9, 9, 16), 16);
  // The crop's north is turned 90 degrees clockwise from the window's: its "north" is east.
  const Pose p = single_frame_pose(frame, {20, 20, 90});
  EXPECT_NEAR(p.u, 24, 1e-9) << "4 cells (2 m) from the crop centre, to the window's east";
  EXPECT_NEAR(p.v, 20, 1e-9);
  EXPECT_NEAR(p.heading_deg, 90, 1e-9);
}

TEST(Baselines, OfflineRecoversAStraightRoute) {
  // A vehicle drives north 2 m per frame; each frame's likelihood is a bump at its true pose in
  // a crop centred on the window, plus a second, false bump that moves randomly.
  const FilterConfig c = config(40, 48, 16);
  std::mt19937 rng(4);
  std::uniform_real_distribution<double> where(1, 7);
  std::vector<std::vector<float>> volumes;
  std::vector<PreparedFrame> frames;
  std::vector<OfflineFrame> input;
  const int n = 6;
  for (int t = 0; t < n; ++t) {
    const double true_v = 30 - 4 * t;  // window row of the vehicle
    auto vol = bump(9, 9, 16, 4, 4, 0);
    const auto noise = bump(9, 9, 16, where(rng), where(rng), 8);
    for (std::size_t i = 0; i < vol.size(); ++i) vol[i] = std::max(vol[i], noise[i] + 0.2f);  // the false bump is higher
    volumes.push_back(vol);
    (void)true_v;
  }
  frames.reserve(static_cast<std::size_t>(n));
  input.reserve(static_cast<std::size_t>(n));
  for (int t = 0; t < n; ++t) frames.push_back(prepare_frame(view(volumes[static_cast<std::size_t>(t)], 9, 9, 16), 16));
  for (int t = 0; t < n; ++t) {
    input.push_back({&frames[static_cast<std::size_t>(t)], CropPose{20, 30.0 - 4 * t, 0}, Odometry{t == 0 ? 0.0 : 2.0, 0, 0}});
  }
  for (int t = 0; t < n; ++t) {
    const Pose single = single_frame_pose(frames[static_cast<std::size_t>(t)], input[static_cast<std::size_t>(t)].crop);
    EXPECT_NE(single.heading_deg, 0.0) << "the single frame is fooled by the false bump";
  }
  const auto poses = offline_poses(input, c);
  for (int t = 0; t < n; ++t) {
    EXPECT_EQ(poses[static_cast<std::size_t>(t)].u, 20) << t;
    EXPECT_EQ(poses[static_cast<std::size_t>(t)].v, 30 - 4 * t) << t;
    EXPECT_EQ(poses[static_cast<std::size_t>(t)].heading_deg, 0) << t;
  }
  const auto windowed = offline_poses(input, c, 1);
  EXPECT_EQ(windowed.size(), static_cast<std::size_t>(n));
  for (int t = 0; t < n; ++t) {
    const Pose at = offline_pose_at(input, static_cast<std::size_t>(t), c, 1);
    EXPECT_EQ(at.u, windowed[static_cast<std::size_t>(t)].u);
    EXPECT_EQ(at.v, windowed[static_cast<std::size_t>(t)].v);
    EXPECT_EQ(at.heading_deg, windowed[static_cast<std::size_t>(t)].heading_deg);
  }
}

// Offline sums all frames, not only those whose crops fall in the window where t's pose is
// sought. The vehicle drives north 4 m a frame; every frame but the first sees two parallel
// "roads", the false one (3 cells east) a little likelier; only the first frame tells them apart.
// Its crop lies beyond the window centred on the last frames, whose poses need it all the same.
TEST(Baselines, OfflineUsesFramesWhoseCropsLieBeyondTheWindow) {
  const FilterConfig c = config(40, 48, 16);
  const int n = 8;
  std::vector<std::vector<float>> volumes;
  volumes.reserve(static_cast<std::size_t>(n));
  for (int t = 0; t < n; ++t) {
    auto vol = bump(9, 9, 16, 4, 4, 0);
    if (t > 0) {
      const auto parallel = bump(9, 9, 16, 4, 7, 0);
      for (std::size_t i = 0; i < vol.size(); ++i) vol[i] = std::max(vol[i], parallel[i] + 0.3f);
    }
    volumes.push_back(vol);
  }
  std::vector<PreparedFrame> frames;
  frames.reserve(static_cast<std::size_t>(n));
  for (const auto& v : volumes) frames.push_back(prepare_frame(view(v, 9, 9, 16), 16));
  std::vector<OfflineFrame> input;
  input.reserve(static_cast<std::size_t>(n));
  for (int t = 0; t < n; ++t) {
    // Window rows 76 (beyond the 48-row window) to 20: 8 cells north a frame.
    input.push_back({&frames[static_cast<std::size_t>(t)], CropPose{20, 76.0 - 8 * t, 0},
                     Odometry{t == 0 ? 0.0 : 4.0, 0, 0}});
  }
  ASSERT_EQ(single_frame_pose(frames[n - 1], input[n - 1].crop).u, 23) << "the last frame alone takes the false road";
  const auto poses = offline_poses(input, c);
  for (int t = 5; t < n; ++t) {  // the frames whose own crops lie in the window
    EXPECT_EQ(poses[static_cast<std::size_t>(t)].u, 20) << t;
    EXPECT_EQ(poses[static_cast<std::size_t>(t)].v, 76 - 8 * t) << t;
    EXPECT_EQ(poses[static_cast<std::size_t>(t)].heading_deg, 0) << t;
  }
}

// The aggregator keeps each frame's placement while the frame stays in range and moves it with
// the window when the window moved by whole cells; every pose must equal a fresh placement's
// (offline_pose_at places every frame anew), for straight and rotated crops, and a window moved
// by a fraction of a cell must not reuse a placement.
TEST(Baselines, OfflineAggregatorReusesPlacementsOnlyWhenExact) {
  FilterConfig c = config(40, 44, 32);
  c.threads = 2;
  std::mt19937 rng(12);
  std::uniform_real_distribution<double> where(2, 8), bin(0, 16), jitter(-0.45, 0.45);
  const int n = 9;
  std::vector<PreparedFrame> frames;
  frames.reserve(static_cast<std::size_t>(n));
  std::vector<OfflineFrame> route;  // crops in region cells
  for (int t = 0; t < n; ++t) {
    auto vol = bump(11, 11, 16, where(rng), where(rng), bin(rng), 1.5);
    const auto other = bump(11, 11, 16, where(rng), where(rng), bin(rng), 1.0);
    for (std::size_t i = 0; i < vol.size(); ++i) vol[i] = std::max(vol[i], other[i] - 0.5f);
    frames.push_back(prepare_frame(view(vol, 11, 11, 16), 32));
    const double rotation = t % 3 == 1 ? 7.0 : 0.0;
    route.push_back({&frames.back(), CropPose{100 + 3.0 * t + jitter(rng), 200 - 2.5 * t + jitter(rng), rotation},
                     Odometry{t == 0 ? 0.0 : 1.6, 0.1 * t, t % 2 ? 9.0 : -4.0}, t});
  }
  for (const double fraction : {0.0, 0.3}) {
    OfflineAggregator aggregator(c);
    for (int t = 0; t < n; ++t) {
      // A window centred on frame t's crop (by whole cells, plus the fraction on odd frames).
      const double ou = std::round(route[static_cast<std::size_t>(t)].crop.centre_u) - 20 - (t % 2 ? fraction : 0.0);
      const double ov = std::round(route[static_cast<std::size_t>(t)].crop.centre_v) - 22;
      std::vector<OfflineFrame> window = route;
      for (auto& f : window) f.crop.centre_u -= ou, f.crop.centre_v -= ov;
      const Pose kept = aggregator.pose_at(window, static_cast<std::size_t>(t), 2);
      const Pose fresh = offline_pose_at(window, static_cast<std::size_t>(t), c, 2);
      EXPECT_EQ(kept.u, fresh.u) << t << " " << fraction;
      EXPECT_EQ(kept.v, fresh.v) << t << " " << fraction;
      EXPECT_EQ(kept.heading_deg, fresh.heading_deg) << t << " " << fraction;
    }
  }
}

TEST(Intake, FewerAndMoreBinsThanTheWindowMapToTheRightHeadings) {
  for (const int bins : {8, 32}) {
    FilterConfig c = config(24, 24, 16);
    c.mgr = false;
    c.pas = false;
    SeqLocFilter filter(c);
    const auto vol = bump(9, 9, bins, 4, 4, bins / 4.0);  // heading 90
    const auto r = filter.step(prepare_frame(view(vol, 9, 9, bins), 16), {12, 12, 0}, {}, {});
    EXPECT_EQ(r.argmax.heading_deg, 90) << bins << " bins";
    EXPECT_EQ(r.argmax.u, 12);
    EXPECT_EQ(r.argmax.v, 12);
  }
}

TEST(Window, RecentreMovesContentAndFillsWithTheMinimum) {
  BeliefVolume b(10, 8, 4);
  std::fill(b.data(), b.data() + b.size(), 0.5f);
  b.prob(2, 3, 1) = 0.9f;
  b.prob(9, 7, 0) = 0.1f;
  b.recentre(-3, 2);  // the window moves 3 cells west and 2 south
  EXPECT_EQ(b.prob(5, 1, 1), 0.9f);
  EXPECT_EQ(b.prob(0, 7, 2), 0.1f) << "entering cells get the minimum";
  EXPECT_EQ(b.prob(0, 0, 3), 0.1f);
}

TEST(Window, RecentreAgreesWithTheCellByCellDefinitionForEveryShift) {
  // Every shift up to past the window's size each way, on 1 and 3 workers, against the
  // definition: new (u, v) = old (u + du, v + dv) where that lies in the window, else the minimum.
  BeliefVolume start(7, 5, 3);
  for (std::size_t i = 0; i < start.size(); ++i) start.data()[i] = 0.25f + static_cast<float>((i * 37) % 101);
  start.prob(6, 4, 2) = 0.125f;  // the minimum
  for (int threads : {1, 3}) {
    for (int dv = -6; dv <= 6; ++dv) {
      for (int du = -8; du <= 8; ++du) {
        BeliefVolume b = start;
        b.recentre(du, dv, start.min_value(), threads);
        int wrong = 0;
        for (int k = 0; k < 3; ++k) {
          for (int v = 0; v < 5; ++v) {
            for (int u = 0; u < 7; ++u) {
              const int su = u + du, sv = v + dv;
              const bool inside = su >= 0 && su < 7 && sv >= 0 && sv < 5;
              wrong += b.prob(u, v, k) != (inside ? start.prob(su, sv, k) : 0.125f);
            }
          }
        }
        EXPECT_EQ(wrong, 0) << "du " << du << " dv " << dv << ", " << threads << " workers";
      }
    }
  }
}

TEST(Window, PredictHandsOverTheBeliefItMovedFrom) {
  FilterConfig c = config(16, 12, 8);
  SeqLocFilter handing(c), plain(c);
  handing.belief().set_gaussian(7, 5, 1.5);
  plain.belief() = handing.belief();
  const BeliefVolume before = handing.belief();
  BeliefVolume previous(16, 12, 8);
  handing.predict({1.5, 0.5, 45}, previous);
  plain.predict({1.5, 0.5, 45});
  EXPECT_TRUE(std::equal(previous.data(), previous.data() + previous.size(), before.data()));
  EXPECT_TRUE(
      std::equal(handing.belief().data(), handing.belief().data() + handing.belief().size(), plain.belief().data()));
  EXPECT_FALSE(std::equal(previous.data(), previous.data() + previous.size(), plain.belief().data()))
      << "the motion moved the belief";
  BeliefVolume wrong(16, 12, 4);
  EXPECT_THROW(handing.predict({1, 0, 0}, wrong), FilterError);
}

TEST(Beyond, SubBinHeadingRefinesBetweenBins) {
  FilterConfig c = config(24, 24, 16);
  c.mgr = false;
  c.subbin_heading = true;
  SeqLocFilter filter(c);
  // True heading 30 degrees = bin 1.333 of 16.
  const auto vol = bump(9, 9, 64, 4, 4, 30.0 / 360.0 * 64, 1.0, 2.0);
  const auto r = filter.step(prepare_frame(view(vol, 9, 9, 64), 16), {12, 12, 0}, {}, {});
  EXPECT_EQ(r.argmax.heading_deg, 22.5);
  EXPECT_LT(std::abs(r.pose.heading_deg - 30.0), std::abs(r.argmax.heading_deg - 30.0));
}

TEST(Beyond, MotionNoiseDiffusesButKeepsMass) {
  FilterConfig c = config(32, 32, 16);
  c.motion_noise = true;
  c.motion_noise_xy_per_m = 0.2;
  c.motion_noise_deg_per_m = 5;
  SeqLocFilter filter(c);
  BeliefVolume& b = filter.belief();
  b.set_gaussian(16, 16, 1.0);
  const float peak_before = *std::max_element(b.data(), b.data() + b.size());
  filter.predict({4.0, 0.0, 0.0});
  const float peak_after = *std::max_element(b.data(), b.data() + b.size());
  EXPECT_LT(peak_after, 0.8f * peak_before) << "the belief spread out";
  EXPECT_NEAR(b.total_probability(), 1.0, 0.02);
  c.motion_noise = false;
  SeqLocFilter plain(c);
  plain.belief().set_gaussian(16, 16, 1.0);
  plain.predict({4.0, 0.0, 0.0});
  const float plain_peak = *std::max_element(plain.belief().data(), plain.belief().data() + plain.belief().size());
  EXPECT_GT(plain_peak, peak_after);
}

TEST(Beyond, GpsPriorPullsTowardsTheFix) {
  FilterConfig c = config(40, 40, 8);
  c.mgr = false;
  c.pas = false;
  c.gps_prior = true;
  SeqLocFilter filter(c);
  std::vector<float> flat(9 * 9 * 8, 0.0f);
  const GpsFix fix{30, 10, 2.0};
  const auto r = filter.step(prepare_frame(view(flat, 9, 9, 8), 8), {20, 20, 0}, {}, {}, fix);
  EXPECT_EQ(r.argmax.u, 30);
  EXPECT_EQ(r.argmax.v, 10);
  c.gps_prior = false;
  SeqLocFilter without(c);
  EXPECT_NE(without.step(prepare_frame(view(flat, 9, 9, 8), 8), {20, 20, 0}, {}, {}, fix).argmax.u, 30);
}

TEST(Beyond, RelocalizationIsFlaggedWhenTheArgmaxJumps) {
  FilterConfig c = config(64, 64, 8);
  c.mgr = false;
  c.etu = false;
  c.relocalization_jump_m = 5;
  SeqLocFilter filter(c);
  const auto here = bump(9, 9, 8, 4, 4, 0);
  auto r = filter.step(prepare_frame(view(here, 9, 9, 8), 8), {20, 40, 0}, {}, {});
  EXPECT_FALSE(r.relocalized);
  r = filter.step(prepare_frame(view(here, 9, 9, 8), 8), {20, 36, 0}, {2, 0, 0}, {});
  EXPECT_FALSE(r.relocalized) << "moved as the odometry says";
  // A much stronger peak 15 m away.
  std::vector<float> there(9 * 9 * 8);
  const auto sharp = bump(9, 9, 8, 4, 4, 0, 0.3, 0.3);
  for (std::size_t i = 0; i < there.size(); ++i) there[i] = 20 * sharp[i];
  // Two frames of it outweigh the two of the old place; the jump is flagged once, when it happens.
  const auto first = filter.step(prepare_frame(view(there, 9, 9, 8), 8), {50, 32, 0}, {2, 0, 0}, {});
  const auto second = filter.step(prepare_frame(view(there, 9, 9, 8), 8), {50, 28, 0}, {2, 0, 0}, {});
  EXPECT_NE(first.relocalized, second.relocalized);
  EXPECT_EQ(second.argmax.u, 50);
  const auto third = filter.step(prepare_frame(view(there, 9, 9, 8), 8), {50, 24, 0}, {2, 0, 0}, {});
  EXPECT_FALSE(third.relocalized);
}

}  // namespace
}  // namespace seqloc::filter

namespace seqloc::filter {
namespace {

// The field table names every field once and each entry reaches its own member: setting one field
// through the table leaves every other field at its default.
TEST(FilterConfigFields, EachNameReachesItsOwnMember) {
  const auto fields = filter_config_fields();
  ASSERT_GE(fields.size(), 19u);
  for (std::size_t i = 0; i < fields.size(); ++i) {
    for (std::size_t j = i + 1; j < fields.size(); ++j) {
      EXPECT_NE(std::string(fields[i].name), fields[j].name);
      EXPECT_NE(fields[i].member, fields[j].member) << fields[i].name << " and " << fields[j].name;
    }
  }
  const FilterConfig defaults;
  auto read = [](const FilterConfig& c, const FilterConfigField& f) {
    return std::visit([&](auto member) { return static_cast<double>(c.*member); }, f.member);
  };
  for (const auto& changed : fields) {
    FilterConfig c;
    std::visit(
        [&](auto member) {
          if constexpr (std::is_same_v<std::remove_reference_t<decltype(c.*member)>, bool>) {
            c.*member = !(c.*member);
          } else {
            c.*member += 1;
          }
        },
        changed.member);
    for (const auto& f : fields) {
      if (&f == &changed) {
        EXPECT_NE(read(c, f), read(defaults, f)) << f.name;
      } else {
        EXPECT_EQ(read(c, f), read(defaults, f)) << f.name << " changed with " << changed.name;
      }
    }
  }
}

// The block form of g (the served road_prior layer, the Python module's crops): each value is the
// scalar g of its distance, runs of equal distances included; g(0) = 1, g(sigma) = e^-1/2.
TEST(RoadPrior, TheBlockFormIsTheScalarGOfEachDistance) {
  const std::vector<float> d = {0.0f, 0.0f, 3.0f, 3.0f, 3.0f, 1.25f, 100.0f, 100.0f, 0.0f, 2.5f};
  const auto g = road_prior_g(d, 3.0);
  ASSERT_EQ(g.size(), d.size());
  for (std::size_t i = 0; i < d.size(); ++i) {
    EXPECT_EQ(g[i], static_cast<float>(road_prior_g(static_cast<double>(d[i]), 3.0))) << i;
  }
  EXPECT_EQ(g[0], 1.0f);
  EXPECT_FLOAT_EQ(g[2], static_cast<float>(std::exp(-0.5)));
  EXPECT_TRUE(road_prior_g(std::vector<float>{}, 3.0).empty());
}

// The CUDA kernels' copy of g (device_math.hpp) is the base layer's, bit for bit.
TEST(RoadPrior, TheDeviceCopyIsTheBaseLayersG) {
  for (const double d : {0.0, 0.5, 1.25, 3.0, 7.5, 40.0, 100.0}) {
    for (const double sigma : {1.0, core::kRoadPriorSigmaM, 8.0}) {
      EXPECT_EQ(math::road_prior_g(d, sigma), core::road_prior_g(d, sigma)) << d << " m, sigma " << sigma;
    }
  }
}

// A crop that is not turned, with another cell size (self-calibration's coarse grid reads the frame
// at twice its cells): sample_slice's separable loop gives every cell the value the per-cell
// sampler math::crop_sample_at gives it, bit for bit, inside, at the edges and outside; a turned
// crop (the per-cell path) for contrast. Fails if the separable loop finds a position or rounds a
// weight otherwise.
TEST(Resample, AnUnturnedCropAtAnotherScaleIsSampledAsCellByCell) {
  const int vh = 37, vw = 29, width = 40, height = 35;
  std::mt19937 rng(7);
  std::uniform_real_distribution<float> value(-30.0f, 0.0f);
  std::vector<float> frame(static_cast<std::size_t>(vh) * vw);
  for (float& x : frame) x = value(rng);
  const auto read = [&frame](std::size_t i) { return frame[i]; };
  int outside = 0;
  for (const double cell_m : {0.25, 1.0, 0.125}) {
    for (const CropPose crop : {CropPose{20.3, 17.8, 0.0}, CropPose{3.0, 30.25, 0.0}, CropPose{20.3, 17.8, 30.0}}) {
      std::vector<float> out(static_cast<std::size_t>(width) * height), blend;
      sample_slice(frame.data(), 1, vh, vw, cell_m, crop, crop.rotation_deg, width, height, 1.0f, blend, out.data());
      const double r = crop.rotation_deg * core::kDegToRad;
      const math::CropMap map{crop.centre_u, crop.centre_v, std::cos(r), std::sin(r), core::kCellM / cell_m, vw, vh};
      int inside = 0;
      for (int v = 0; v < height; ++v) {
        for (int u = 0; u < width; ++u) {
          const float expected = math::crop_sample_at(map, u, v, 1.0f, read);
          inside += expected != 1.0f;
          ASSERT_EQ(out[static_cast<std::size_t>(v) * width + u], expected)
              << "cell (" << u << ", " << v << "), " << cell_m << " m cells, crop turned " << crop.rotation_deg;
        }
      }
      EXPECT_GT(inside, 0) << cell_m;
      outside += width * height - inside;
    }
  }
  EXPECT_GT(outside, 0);
}

}  // namespace
}  // namespace seqloc::filter
