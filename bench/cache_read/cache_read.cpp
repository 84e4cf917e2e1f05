// bench/cache_read: the cost of reading one 512 x 512 tile from a region cache (SQLite fetch +
// PNG decode), every tile of both layers, LRU disabled (capacity 1, tiles alternate). The peer is
// a memcpy of the decoded tile. Prints ms per tile (mean, p50, p99) and one JSON line.
//
//   cache_read REGION.gpkg

#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstring>
#include <vector>

#include "seqloc/raster/cache.hpp"

namespace {

using Clock = std::chrono::steady_clock;

struct Stats {
  double mean_ms, p50_ms, p99_ms;
};

Stats summarize(std::vector<double> ms) {
  std::sort(ms.begin(), ms.end());
  double sum = 0;
  for (double m : ms) sum += m;
  return {sum / static_cast<double>(ms.size()), ms[ms.size() / 2], ms[ms.size() * 99 / 100]};
}

}  // namespace

int main(int argc, char** argv) {
  if (argc != 2) {
    std::fprintf(stderr, "usage: cache_read REGION.gpkg\n");
    return 2;
  }
  seqloc::raster::CacheReader reader(argv[1], 1);
  const auto& grid = reader.grid();
  std::vector<double> classes_ms, distance_ms;
  std::size_t checksum = 0;
  for (std::int64_t row = 0; row < grid.tiles_high(); ++row) {
    for (std::int64_t col = 0; col < grid.tiles_wide(); ++col) {
      auto t0 = Clock::now();
      const auto rgb = reader.classes_tile(col, row);
      classes_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
      t0 = Clock::now();
      const auto cm = reader.distance_tile(col, row);
      distance_ms.push_back(std::chrono::duration<double, std::milli>(Clock::now() - t0).count());
      checksum += (*rgb)[12345] + (*cm)[4321];
    }
  }
  // Peer: copying a decoded class tile (786 KB), the floor of any read that hands out a buffer.
  std::vector<std::uint8_t> src(std::size_t{512} * 512 * 3, 1), dst(src.size());
  const int copies = 2000;
  const auto t0 = Clock::now();
  for (int i = 0; i < copies; ++i) {
    src[static_cast<std::size_t>(i) % src.size()] = static_cast<std::uint8_t>(i);
    std::memcpy(dst.data(), src.data(), src.size());
    checksum += dst[static_cast<std::size_t>(i * 7) % dst.size()];
  }
  const double memcpy_ms = std::chrono::duration<double, std::milli>(Clock::now() - t0).count() / copies;
  const Stats c = summarize(classes_ms), d = summarize(distance_ms);
  std::printf("tiles read: %zu per layer (checksum %zu)\n", classes_ms.size(), checksum);
  std::printf("classes tile:       mean %.3f ms, p50 %.3f ms, p99 %.3f ms\n", c.mean_ms, c.p50_ms, c.p99_ms);
  std::printf("road_distance tile: mean %.3f ms, p50 %.3f ms, p99 %.3f ms\n", d.mean_ms, d.p50_ms, d.p99_ms);
  std::printf("memcpy of a decoded class tile: %.3f ms (read / memcpy: classes %.1fx, distance %.1fx)\n", memcpy_ms,
              c.mean_ms / memcpy_ms, d.mean_ms / memcpy_ms);
  std::printf("{\"benchmark\": \"cache_read\", \"tiles\": %zu, \"classes_ms_mean\": %.4f, \"classes_ms_p99\": %.4f, "
              "\"distance_ms_mean\": %.4f, \"distance_ms_p99\": %.4f, \"memcpy_ms\": %.4f}\n",
              classes_ms.size(), c.mean_ms, c.p99_ms, d.mean_ms, d.p99_ms, memcpy_ms);
  return 0;
}
