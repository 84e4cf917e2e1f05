#include "seqloc/raster/distance_transform.hpp"

#include <algorithm>
#include <cmath>
#include <cassert>
#include <limits>

namespace seqloc::raster {

void squared_distance(std::span<const std::uint8_t> mask, int width, int height, int out_u0, int out_v0, int out_w,
                      int out_h, DistanceScratch& scratch, std::vector<std::uint32_t>& out, int reach) {
  assert(mask.size() == static_cast<std::size_t>(width) * static_cast<std::size_t>(height));
  assert(out_u0 >= 0 && out_v0 >= 0 && out_u0 + out_w <= width && out_v0 + out_h <= height);
  assert(width < 0xFFFF && height < 0xFFFF);
  const auto W = static_cast<std::size_t>(width);
  // Column pass, row by row so that the inner loops run over contiguous memory: distance (in
  // cells) to the nearest mark above, then below, for the output rows only. kFar stands for "no
  // mark in reach"; it exceeds any real distance in the window.
  const std::uint16_t kFar = static_cast<std::uint16_t>(
      reach > 0 ? std::min(reach + 1, 0xFFFF) : std::min(std::max(width, height) + 1, 0xFFFF));
  auto& column = scratch.column;
  column.resize(static_cast<std::size_t>(out_h) * W);
  auto& up = scratch.up;
  up.assign(W, kFar);
  const int first_row = reach > 0 ? std::max(0, out_v0 - reach) : 0;
  for (int v = first_row; v < out_v0 + out_h; ++v) {
    const std::uint8_t* m = mask.data() + static_cast<std::size_t>(v) * W;
    std::uint16_t* u16 = up.data();
    for (std::size_t u = 0; u < W; ++u) {
      const std::uint16_t next = static_cast<std::uint16_t>(std::min<int>(u16[u] + 1, kFar));
      u16[u] = m[u] ? 0 : next;
    }
    if (v >= out_v0) std::copy(up.begin(), up.end(), column.begin() + static_cast<std::ptrdiff_t>((v - out_v0) * W));
  }
  up.assign(W, kFar);
  const int last_row = reach > 0 ? std::min(height - 1, out_v0 + out_h - 1 + reach) : height - 1;
  for (int v = last_row; v >= out_v0; --v) {
    const std::uint8_t* m = mask.data() + static_cast<std::size_t>(v) * W;
    std::uint16_t* u16 = up.data();
    for (std::size_t u = 0; u < W; ++u) {
      const std::uint16_t next = static_cast<std::uint16_t>(std::min<int>(u16[u] + 1, kFar));
      u16[u] = m[u] ? 0 : next;
    }
    if (v < out_v0 + out_h) {
      std::uint16_t* c = column.data() + static_cast<std::size_t>(v - out_v0) * W;
      for (std::size_t u = 0; u < W; ++u) c[u] = std::min(c[u], u16[u]);
    }
  }

  // Row pass: lower envelope of the parabolas (u - q)^2 + c(q)^2 over the columns q with a mark
  // in reach.
  out.assign(static_cast<std::size_t>(out_w) * static_cast<std::size_t>(out_h), kNoMark);
  auto& hull_q = scratch.hull_q;
  auto& hull_z = scratch.hull_z;
  hull_q.resize(W);
  hull_z.resize(W + 1);
  const int q_first = reach > 0 ? std::max(0, out_u0 - reach) : 0;
  const int q_last = reach > 0 ? std::min(width - 1, out_u0 + out_w - 1 + reach) : width - 1;
  for (int r = 0; r < out_h; ++r) {
    const std::uint16_t* c = column.data() + static_cast<std::size_t>(r) * W;
    int k = -1;
    for (int q = q_first; q <= q_last; ++q) {
      if (c[q] >= kFar) continue;
      const double fq = static_cast<double>(c[q]) * c[q] + static_cast<double>(q) * q;
      double s = -std::numeric_limits<double>::infinity();
      while (k >= 0) {
        const int p = hull_q[static_cast<std::size_t>(k)];
        s = (fq - (static_cast<double>(c[p]) * c[p] + static_cast<double>(p) * p)) / (2.0 * (q - p));
        if (s > hull_z[static_cast<std::size_t>(k)]) break;
        --k;
      }
      ++k;
      hull_q[static_cast<std::size_t>(k)] = q;
      hull_z[static_cast<std::size_t>(k)] = k == 0 ? -std::numeric_limits<double>::infinity() : s;
    }
    if (k < 0) continue;  // no mark reaches this row
    std::uint32_t* o = out.data() + static_cast<std::size_t>(r) * static_cast<std::size_t>(out_w);
    int j = 0;
    for (int u = out_u0; u < out_u0 + out_w; ++u) {
      while (j < k && hull_z[static_cast<std::size_t>(j) + 1] < u) ++j;
      const int q = hull_q[static_cast<std::size_t>(j)];
      const auto du = static_cast<std::uint32_t>(u > q ? u - q : q - u);
      o[u - out_u0] = du * du + static_cast<std::uint32_t>(c[q]) * c[q];
    }
  }
}

DistanceQuantizer::DistanceQuantizer(double cell_m, std::uint16_t max_cm)
    : max_cm_(max_cm), reach_(static_cast<int>(std::ceil(max_cm / (cell_m * 100.0)))) {
  // Every squared distance whose value is below the clamp.
  std::uint32_t d2 = 0;
  while (quantize_distance_cm(d2, cell_m, max_cm) < max_cm) {
    table_.push_back(quantize_distance_cm(d2, cell_m, max_cm));
    ++d2;
  }
}

std::vector<double> brute_force_distance_m(std::span<const std::uint8_t> mask, int width, int height, double cell_m) {
  std::vector<std::pair<int, int>> marks;
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      if (mask[static_cast<std::size_t>(v) * static_cast<std::size_t>(width) + static_cast<std::size_t>(u)]) {
        marks.emplace_back(u, v);
      }
    }
  }
  std::vector<double> out(static_cast<std::size_t>(width) * static_cast<std::size_t>(height),
                          std::numeric_limits<double>::max());
  for (int v = 0; v < height; ++v) {
    for (int u = 0; u < width; ++u) {
      double best = std::numeric_limits<double>::max();
      for (const auto& [mu, mv] : marks) {
        const double dx = (u - mu) * cell_m, dy = (v - mv) * cell_m;
        best = std::min(best, std::sqrt(dx * dx + dy * dy));
      }
      out[static_cast<std::size_t>(v) * static_cast<std::size_t>(width) + static_cast<std::size_t>(u)] = best;
    }
  }
  return out;
}

}  // namespace seqloc::raster
