#include "seqloc/offline/offline.hpp"

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>
#include <limits>
#include <map>
#include <utility>

#include <Eigen/Core>

#include "seqloc/core/angles.hpp"
#include "seqloc/core/thread_pool.hpp"
#include "seqloc/core/units.hpp"
#include "seqloc/filter/aligned.hpp"
#include "seqloc/filter/resample.hpp"

namespace seqloc::offline {

namespace {

using ArrayMap = Eigen::Map<Eigen::ArrayXf>;
using ConstArrayMap = Eigen::Map<const Eigen::ArrayXf>;
using filter::AlignedVector;
using filter::BeliefVolume;
using filter::bin_heading_deg;

using core::kCellM;

// Frames are placed and warped as probabilities relative to their peak, and only then turned
// into log-likelihoods to add up. Bilinear interpolation of probabilities moves mass between
// cells; of log-probabilities it turns a peak beside log(0) into log(0), so a route of sharp
// volumes off the cell lattice lost every observed cell and its sum peaked where no frame looked.
// A relative probability below the floor (69 nats under the frame's peak) counts as the floor.
constexpr float kRelativeFloor = 1e-30f;

// Motion from frame s to frame t: the increments in between, inverted when s is later.
Odometry motion_between(const std::vector<OfflineFrame>& frames, std::size_t s, std::size_t t) {
  std::vector<Odometry> steps;
  for (std::size_t i = std::min(s, t) + 1; i <= std::max(s, t); ++i) steps.push_back(frames[i].from_previous);
  const Odometry m = compose(steps);
  return s > t ? invert(m) : m;
}

bool whole(double x) { return std::abs(x - std::round(x)) < 1e-9; }

}  // namespace

// A frame's relative probabilities p / p_max resampled at every window heading, on a canvas
// that covers its crop's footprint with a margin; NaN where the crop does not reach (NaN
// survives interpolation, so a cell half outside stays unobserved). Canvas cell (0, 0) is window
// cell (u0, v0) of the window in which the crop centre was (centre_u, centre_v).
struct OfflineAggregator::Canvas {
  const PreparedFrame* frame = nullptr;
  CropPose crop;
  int u0 = 0, v0 = 0;
  BeliefVolume values;
};

struct OfflineAggregator::Impl {
  std::map<std::int64_t, Canvas> kept;  // by OfflineFrame::key
  AlignedVector<float> relative;
  std::vector<float> blend;
};

OfflineAggregator::OfflineAggregator(const FilterConfig& config)
    : config_((config.validate(), config)), impl_(std::make_unique<Impl>()) {}

OfflineAggregator::~OfflineAggregator() = default;
OfflineAggregator::OfflineAggregator(OfflineAggregator&&) noexcept = default;
OfflineAggregator& OfflineAggregator::operator=(OfflineAggregator&&) noexcept = default;

OfflineAggregator::Canvas OfflineAggregator::place(const OfflineFrame& f) {
  const PreparedFrame& p = *f.frame;
  // The footprint: the crop's rectangle (window cells) turned by its rotation.
  const double scale = p.cell_m / kCellM, r = f.crop.rotation_deg * core::kDegToRad;
  const double half_w = p.width * scale / 2, half_h = p.height * scale / 2;
  const double c = std::abs(std::cos(r)), s = std::abs(std::sin(r));
  const double extent_u = half_w * c + half_h * s, extent_v = half_w * s + half_h * c;
  const int u0 = static_cast<int>(std::floor(f.crop.centre_u - extent_u)) - 1;
  const int v0 = static_cast<int>(std::floor(f.crop.centre_v - extent_v)) - 1;
  const int u1 = static_cast<int>(std::ceil(f.crop.centre_u + extent_u)) + 1;
  const int v1 = static_cast<int>(std::ceil(f.crop.centre_v + extent_v)) + 1;
  Canvas canvas{&p, f.crop, u0, v0, BeliefVolume(u1 - u0 + 1, v1 - v0 + 1, config_.headings)};
  auto& relative = impl_->relative;
  relative.resize(p.log_prob.size());
  ArrayMap(relative.data(), static_cast<Eigen::Index>(relative.size())) =
      (ConstArrayMap(p.log_prob.data(), static_cast<Eigen::Index>(p.log_prob.size())) - p.max_log_prob).exp();
  const CropPose local{f.crop.centre_u - u0, f.crop.centre_v - v0, f.crop.rotation_deg};
  auto& values = canvas.values;
  for (int k = 0; k < values.headings(); ++k) {
    filter::sample_slice(relative.data(), p.bins, p.height, p.width, p.cell_m, local, values.bin_heading_deg(k),
                         values.width(), values.height(), std::numeric_limits<float>::quiet_NaN(), impl_->blend,
                         values.slice(k));
  }
  return canvas;
}

namespace {

// The part of the window where frame t observes, and the sum of the frames' log-likelihoods
// over it, bin-major ((bin, row, column) in the box).
struct SumBox {
  int u0 = 0, v0 = 0, width = 0, height = 0;
  std::size_t cells = 0;  ///< width * height
  AlignedVector<float> sum;
  std::vector<float> own;  ///< frame t's values in the box (NaN where it does not observe)
};

// The box of frame t's canvas (its cell (0, 0) at window cell `origin`) within a W x H window;
// the whole window when the canvas lies outside it.
SumBox observed_box(const std::array<int, 2>& origin, const BeliefVolume& own, int W, int H, int R) {
  int bu0 = std::max(0, origin[0]), bv0 = std::max(0, origin[1]);
  int bu1 = std::min(W - 1, origin[0] + own.width() - 1);
  int bv1 = std::min(H - 1, origin[1] + own.height() - 1);
  if (bu0 > bu1 || bv0 > bv1) bu0 = 0, bv0 = 0, bu1 = W - 1, bv1 = H - 1;  // frame t's crop outside the window
  SumBox box;
  box.u0 = bu0;
  box.v0 = bv0;
  box.width = bu1 - bu0 + 1;
  box.height = bv1 - bv0 + 1;
  box.cells = static_cast<std::size_t>(box.width) * static_cast<std::size_t>(box.height);
  box.sum.assign(box.cells * static_cast<std::size_t>(R), 0.0f);
  box.own.resize(box.sum.size());
  return box;
}

// One frame's log-likelihood added to the sum: `relative` (its values over its maximum, in the
// box, for bin k) where it observed the cell, log(1/M) - outside_crop_nats where not
// (conventions.md section 6 step 3).
class FrameTerm {
 public:
  FrameTerm(SumBox& box, const PreparedFrame& frame, const FilterConfig& config)
      : box_(box),
        no_info_(static_cast<float>(-frame.log_cells - config.outside_crop_nats)),
        max_log_prob_(frame.max_log_prob) {}
  void add(const float* relative, int k) const {
    const ConstArrayMap p(relative, static_cast<Eigen::Index>(box_.cells));
    ArrayMap(box_.sum.data() + static_cast<std::size_t>(k) * box_.cells, static_cast<Eigen::Index>(box_.cells)) +=
        p.isNaN().select(no_info_, p.max(kRelativeFloor).log() + max_log_prob_);
  }

 private:
  SumBox& box_;
  float no_info_, max_log_prob_;
};

// Frame t itself, its canvas `values` with cell (0, 0) at window cell `origin`: kept in
// box.own too.
void add_own_frame(SumBox& box, const BeliefVolume& values, const std::array<int, 2>& origin,
                   const PreparedFrame& frame, const FilterConfig& config) {
  const FrameTerm term(box, frame, config);
  const double ou = box.u0 - origin[0], ov = box.v0 - origin[1];  // box cell -> canvas cell
  const float nan = std::numeric_limits<float>::quiet_NaN();
  core::parallel_chunks(values.headings(), config.threads, [&](int k0, int k1, int) {
    for (int k = k0; k < k1; ++k) {
      float* dst = box.own.data() + static_cast<std::size_t>(k) * box.cells;
      filter::translate(values.slice(k), values.width(), values.height(), dst, box.width, box.height, ou, ov, nan);
      term.add(dst, k);
    }
  });
}

// Frame s warped to t by `motion` (s's pose to t's): box bin k takes canvas bins k + shift and
// k + shift + 1 (heading k * 360 / R + yaw), weights 1 - a and a, each moved back by the motion
// at its heading.
void add_warped_frame(SumBox& box, const BeliefVolume& values, const std::array<int, 2>& origin,
                      const PreparedFrame& frame, const Odometry& motion, const FilterConfig& config) {
  const FrameTerm term(box, frame, config);
  const int R = values.headings();
  const double ou = box.u0 - origin[0], ov = box.v0 - origin[1];  // box cell -> canvas cell
  const float nan = std::numeric_limits<float>::quiet_NaN();
  const double p = motion.yaw_deg * R / 360.0, floor_p = std::floor(p);
  const auto a = static_cast<float>(p - floor_p);
  const int shift = static_cast<int>(((static_cast<long long>(floor_p) % R) + R) % R);
  // The whole canvas counts, wherever the frame's crop lies: the window only bounds where t's
  // pose is sought. (Reading only the part of a crop inside the window, as if the frames were
  // placed in it, dropped every frame whose crop lay beyond it, so aggregating more frames made
  // the poses worse: 38.6 % R@5m with all frames against 45.3 % with +-10 on a development set.)
  auto translated = [&](int j, float* dst) {
    double du = 0, dv = 0;
    filter::displacement_cells(motion, values.bin_heading_deg(j), du, dv);
    filter::translate(values.slice(j), values.width(), values.height(), dst, box.width, box.height, ou - du, ov - dv,
                      nan);
  };
  core::parallel_chunks(R, config.threads, [&](int k0, int k1, int) {
    std::vector<float> buffer_a(box.cells), buffer_b(box.cells), mixed(box.cells);
    float* current = buffer_a.data();
    float* next = buffer_b.data();
    translated((k0 + shift) % R, current);
    for (int k = k0; k < k1; ++k) {
      if (a == 0.0f) {
        term.add(current, k);
        if (k + 1 < k1) translated((k + 1 + shift) % R, current);
        continue;
      }
      translated((k + shift + 1) % R, next);
      for (std::size_t i = 0; i < box.cells; ++i) mixed[i] = (1 - a) * current[i] + a * next[i];
      term.add(mixed.data(), k);
      std::swap(current, next);
    }
  });
}

// The sum's argmax among the cells frame t observes (elsewhere the sum is made of "no
// information" terms); the whole box when it observes none.
Pose sum_argmax(const SumBox& box, int R) {
  const auto& sum = box.sum;
  std::ptrdiff_t best = -1;
  float top = -std::numeric_limits<float>::infinity();
  for (std::size_t i = 0; i < sum.size(); ++i) {
    if (!std::isnan(box.own[i]) && (best < 0 || sum[i] > top)) {
      best = static_cast<std::ptrdiff_t>(i);
      top = sum[i];
    }
  }
  if (best < 0) best = std::max_element(sum.begin(), sum.end()) - sum.begin();
  const auto k = static_cast<int>(static_cast<std::size_t>(best) / box.cells);
  const auto rest = static_cast<std::size_t>(best) % box.cells;
  const auto u = box.u0 + static_cast<int>(rest % static_cast<std::size_t>(box.width));
  const auto v = box.v0 + static_cast<int>(rest / static_cast<std::size_t>(box.width));
  return {static_cast<double>(u), static_cast<double>(v), bin_heading_deg(k, R)};
}

}  // namespace

Pose OfflineAggregator::pose_at(const std::vector<OfflineFrame>& frames, std::size_t t, int half_window) {
  const std::size_t n = frames.size();
  const auto k_half = static_cast<std::size_t>(half_window);
  const std::size_t s0 = half_window < 0 ? 0 : (t > k_half ? t - k_half : 0);
  const std::size_t s1 = half_window < 0 ? n - 1 : std::min(n - 1, t + k_half);

  // Each frame's canvas, and where its cell (0, 0) lies in this window. A kept canvas serves
  // again when its crop moved by whole cells (a window re-centred on another frame).
  std::map<std::size_t, Canvas> local;
  std::vector<std::pair<const Canvas*, std::array<int, 2>>> placed;
  for (std::size_t s = s0; s <= s1; ++s) {
    const OfflineFrame& f = frames[s];
    const Canvas* canvas = nullptr;
    if (f.key >= 0) {
      auto it = impl_->kept.find(f.key);
      if (it != impl_->kept.end()) {
        const Canvas& k = it->second;
        const double du = f.crop.centre_u - k.crop.centre_u, dv = f.crop.centre_v - k.crop.centre_v;
        if (k.frame != f.frame || k.crop.rotation_deg != f.crop.rotation_deg || !whole(du) || !whole(dv)) {
          impl_->kept.erase(it);
          it = impl_->kept.end();
        }
      }
      if (it == impl_->kept.end()) it = impl_->kept.emplace(f.key, place(f)).first;
      canvas = &it->second;
    } else {
      canvas = &local.emplace(s, place(f)).first->second;
    }
    const int u0 = canvas->u0 + static_cast<int>(std::lround(f.crop.centre_u - canvas->crop.centre_u));
    const int v0 = canvas->v0 + static_cast<int>(std::lround(f.crop.centre_v - canvas->crop.centre_v));
    placed.push_back({canvas, {u0, v0}});
  }
  // Canvases of frames no longer in range are dropped.
  for (auto it = impl_->kept.begin(); it != impl_->kept.end();) {
    const bool used = std::any_of(placed.begin(), placed.end(), [&](const auto& p) { return p.first == &it->second; });
    it = used ? std::next(it) : impl_->kept.erase(it);
  }

  // The sum is needed only where frame t observes: the box of its canvas within the window.
  const auto& [own, own_origin] = placed[t - s0];
  SumBox box = observed_box(own_origin, own->values, config_.width, config_.height, config_.headings);
  for (std::size_t s = s0; s <= s1; ++s) {
    const auto& [canvas, origin] = placed[s - s0];
    if (s == t) {
      add_own_frame(box, canvas->values, origin, *frames[s].frame, config_);
    } else {
      add_warped_frame(box, canvas->values, origin, *frames[s].frame, motion_between(frames, s, t), config_);
    }
  }
  return sum_argmax(box, config_.headings);
}

Pose offline_pose_at(const std::vector<OfflineFrame>& frames, std::size_t t, const FilterConfig& config,
                     int half_window) {
  OfflineAggregator aggregator(config);
  return aggregator.pose_at(frames, t, half_window);
}

std::vector<Pose> offline_poses(std::vector<OfflineFrame> frames, const FilterConfig& config, int half_window) {
  // One window for every t: each frame placed once.
  for (std::size_t s = 0; s < frames.size(); ++s) frames[s].key = static_cast<std::int64_t>(s);
  OfflineAggregator aggregator(config);
  std::vector<Pose> poses;
  poses.reserve(frames.size());
  for (std::size_t t = 0; t < frames.size(); ++t) poses.push_back(aggregator.pose_at(frames, t, half_window));
  return poses;
}

}  // namespace seqloc::offline
