#pragma once
// A frame volume's values for the intake and filter tests: (H, W, N) floats and a view of them as
// log-probabilities, and one drawn at random.

#include <cstddef>
#include <random>
#include <vector>

#include "seqloc/core/volume.hpp"

namespace seqloc::test {

struct Volume {
  std::vector<float> values;
  [[nodiscard]] core::FrameVolume view(int h, int w, int n, double cell_m = 0.5) const {
    core::FrameVolume f;
    f.data = values.data();
    f.height = h;
    f.width = w;
    f.bins = n;
    f.cell_m = cell_m;
    return f;
  }
};

/// Log-probabilities drawn from N(0, 2^2), not normalized.
inline Volume random_volume(std::mt19937& rng, int h, int w, int n) {
  std::normal_distribution<float> d(0.0f, 2.0f);
  Volume v;
  v.values.resize(static_cast<std::size_t>(h * w * n));
  for (auto& x : v.values) x = d(rng);
  return v;
}

}  // namespace seqloc::test
