// bench/filter: one full SeqLoc step (frame intake and normalization, predict, ETU, update, MGR,
// PAS) for 128x128x256 and 256x256x256 windows with 1 and 2 threads, self-calibration off, on (the
// one-step criterion, the default) and with its bank (--self-calibration-bank), against a memcpy of
// the belief volume measured in the same run. The variants step in turn, round by round; each row is
// the median of 24 steps. Prints ms/step, frames/s, step / memcpy, step / self-calibration off's, one
// JSON line.

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "seqloc/filter/seqloc_filter.hpp"

namespace {

using Clock = std::chrono::steady_clock;
using seqloc::filter::FilterConfig;

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  return v[v.size() / 2];
}

struct Row {
  int size;
  int threads;
  bool calibrate, bank;
  double step_ms, memcpy_ms, intake_ms;
  double over_off;  ///< step / the same window and threads' step without self-calibration
};

}  // namespace

int main() {
  std::mt19937 rng(42);
  std::normal_distribution<float> noise(0, 2);
  // A 128 x 128 x 256 frame volume (64 m crops at 0.5 m, like OrienterNet's), random log-probs.
  const int vh = 128, vw = 128, vn = 256;
  std::vector<float> volume(static_cast<std::size_t>(vh) * vw * vn);
  for (auto& x : volume) x = noise(rng);
  const seqloc::filter::FrameVolume view{
      volume.data(), seqloc::filter::VolumeType::float32, seqloc::filter::VolumeValues::log_prob, vh, vw, vn, 0.5};
  std::vector<Row> rows;
  for (const int size : {128, 256}) {
    for (const int threads : {1, 2}) {
      // The three variants step in turn, round by round, so that a machine whose speed drifts (other
      // tenants, turbo) slows them alike: their ratios are of one moment's speed.
      struct Variant {
        bool calibrate, bank;
        std::unique_ptr<seqloc::filter::SeqLocFilter> filter;
        std::vector<double> step_ms, intake_ms;
      };
      std::vector<Variant> variants;
      for (const int variant : {0, 1, 2}) {
        FilterConfig c;
        c.width = c.height = size;
        c.headings = 256;
        c.threads = threads;
        c.self_calibrate = variant > 0;
        c.self_calibration_bank = variant == 2;
        variants.push_back({variant > 0, variant == 2, std::make_unique<seqloc::filter::SeqLocFilter>(c), {}, {}});
      }
      std::vector<float> road(static_cast<std::size_t>(size) * size);
      for (int v = 0; v < size; ++v)
        for (int u = 0; u < size; ++u)
          road[static_cast<std::size_t>(v) * static_cast<std::size_t>(size) + static_cast<std::size_t>(u)] =
              static_cast<float>(std::abs(u - size / 2) * 0.5);
      constexpr int kWarmUp = 2, kRounds = 24;
      for (int i = 0; i < kWarmUp + kRounds; ++i) {
        for (Variant& variant : variants) {
          const auto t0 = Clock::now();
          const auto frame = seqloc::filter::prepare_frame(view, 256, threads);
          const auto t1 = Clock::now();
          const auto r =
              variant.filter->step(frame, {size / 2.0 + (i % 3), size / 2.0 - (i % 2), 0}, {3.7, 0.2, 4.3}, road);
          const auto t2 = Clock::now();
          if (r.pose.u < -1e9) std::puts("");  // keep the result alive
          if (i < kWarmUp) continue;
          variant.intake_ms.push_back(std::chrono::duration<double, std::milli>(t1 - t0).count());
          variant.step_ms.push_back(std::chrono::duration<double, std::milli>(t2 - t0).count());
        }
      }
      // Peer: memcpy of the belief volume (W x H x R floats).
      const auto& b = variants.front().filter->belief();
      std::vector<float> copy(b.size());
      std::vector<double> copy_ms;
      for (int i = 0; i < 10; ++i) {
        const auto t0 = Clock::now();
        std::memcpy(copy.data(), b.data(), b.size() * sizeof(float));
        copy_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
      }
      const double off_ms = median(variants.front().step_ms);
      for (const Variant& variant : variants) {
        const double step_ms = median(variant.step_ms);
        rows.push_back({size, threads, variant.calibrate, variant.bank, step_ms, median(copy_ms),
                        median(variant.intake_ms), step_ms / off_ms});
        const Row& r = rows.back();
        std::printf(
            "%dx%dx256, %d thread%s, self-calibration %s: %.1f ms/step (volume intake %.1f ms), %.1f frames/s; memcpy "
            "of the belief (%.0f MB) %.2f ms; step / memcpy = %.1f; step / self-calibration off's = %.2f\n",
            size, size, threads, threads > 1 ? "s" : "",
            variant.bank        ? "bank"
            : variant.calibrate ? "on "
                                : "off",
            r.step_ms, r.intake_ms, 1000.0 / r.step_ms, static_cast<double>(b.size()) * 4 / 1e6, r.memcpy_ms,
            r.step_ms / r.memcpy_ms, r.over_off);
      }
    }
  }
  std::string json = R"({"benchmark": "filter", "volume": "128x128x256 float32", "rows": [)";
  for (std::size_t i = 0; i < rows.size(); ++i) {
    char buffer[256];
    std::snprintf(buffer, sizeof buffer,
                  "%s{\"window\": %d, \"threads\": %d, \"self_calibrate\": %s, \"bank\": %s, \"ms_per_step\": %.2f, "
                  "\"intake_ms\": "
                  "%.2f, \"frames_per_s\": %.2f, "
                  "\"memcpy_ms\": %.3f, \"step_over_memcpy\": %.2f, \"step_over_self_calibration_off\": %.3f}",
                  i ? ", " : "", rows[i].size, rows[i].threads, rows[i].calibrate ? "true" : "false",
                  rows[i].bank ? "true" : "false", rows[i].step_ms, rows[i].intake_ms, 1000.0 / rows[i].step_ms,
                  rows[i].memcpy_ms, rows[i].step_ms / rows[i].memcpy_ms, rows[i].over_off);
    json += buffer;
  }
  std::printf("%s]}\n", json.c_str());
  return 0;
}
