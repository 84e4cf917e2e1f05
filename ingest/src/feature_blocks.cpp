#include "feature_blocks.hpp"

#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <cstring>
#include <stdexcept>
#include <string>
#include <tuple>
#include <type_traits>

#include "seqloc/core/error.hpp"
#include "seqloc/core/files.hpp"

namespace seqloc::ingest::detail {
namespace {

using raster::PixelBox;
using raster::PixelNode;
using raster::RegionGrid;

enum Kind : std::uint8_t { kNode, kLine, kArea };

class Writer {
 public:
  template <class T>
  void put(const T& value) {
    static_assert(std::is_trivially_copyable_v<T>);
    const auto* bytes = reinterpret_cast<const char*>(&value);
    buffer_.insert(buffer_.end(), bytes, bytes + sizeof(T));
  }
  void put_pixels(const std::vector<raster::Pixel>& pixels) {
    put(static_cast<std::uint32_t>(pixels.size()));
    const auto* bytes = reinterpret_cast<const char*>(pixels.data());
    buffer_.insert(buffer_.end(), bytes, bytes + pixels.size() * sizeof(raster::Pixel));
  }
  [[nodiscard]] std::size_t size() const { return buffer_.size(); }
  void flush(int fd, const std::filesystem::path& dir) {
    std::size_t done = 0;
    while (done < buffer_.size()) {
      const ssize_t n = ::write(fd, buffer_.data() + done, buffer_.size() - done);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) {
        throw IoError("cannot write the features' spill file in " + dir.string() + ": " +
                      std::strerror(n < 0 ? errno : ENOSPC));
      }
      done += static_cast<std::size_t>(n);
    }
    buffer_.clear();
  }

 private:
  std::vector<char> buffer_;
};

class Reader {
 public:
  explicit Reader(std::vector<char> bytes) : bytes_(std::move(bytes)) {}
  template <class T>
  T get() {
    T value{};
    std::memcpy(&value, bytes_.data() + at_, sizeof(T));
    at_ += sizeof(T);
    return value;
  }
  std::vector<raster::Pixel> get_pixels(PixelBox& box) {
    std::vector<raster::Pixel> pixels(get<std::uint32_t>());
    std::memcpy(pixels.data(), bytes_.data() + at_, pixels.size() * sizeof(raster::Pixel));
    at_ += pixels.size() * sizeof(raster::Pixel);
    for (const auto& p : pixels) box.extend(p);
    return pixels;
  }

 private:
  std::vector<char> bytes_;
  std::size_t at_ = 0;
};

}  // namespace

// One (block, feature) pair; sorted by block, then kind, then index (the features' own order).
struct FeatureBlocks::Entry {
  std::uint32_t block;
  Kind kind;
  std::uint32_t index;
  friend bool operator<(const Entry& a, const Entry& b) {
    return std::tie(a.block, a.kind, a.index) < std::tie(b.block, b.kind, b.index);
  }
};

FeatureBlocks::FeatureBlocks(const raster::RegionFeatures& features, const RegionGrid& grid, int halo_px,
                             int block_tiles, const std::filesystem::path& spill_dir)
    : grid_(grid), block_tiles_(block_tiles), dir_(spill_dir) {
  blocks_wide_ = (grid.tiles_wide() + block_tiles - 1) / block_tiles;
  blocks_high_ = (grid.tiles_high() + block_tiles - 1) / block_tiles;
  const auto block_count = static_cast<std::size_t>(blocks_wide_ * blocks_high_);

  // Which blocks each feature meets, as the renderer's tile bins would (roads with the halo).
  std::vector<Entry> entries;
  auto add = [&](const PixelBox& box, std::int64_t margin, Kind kind, std::size_t index) {
    const raster::TileSpan t = raster::tiles_meeting(grid, box, margin);
    const std::int64_t c0 = t.c0, c1 = t.c1, r0 = t.r0, r1 = t.r1;
    for (std::int64_t by = r0 / block_tiles; r0 <= r1 && by <= r1 / block_tiles; ++by) {
      for (std::int64_t bx = c0 / block_tiles; c0 <= c1 && bx <= c1 / block_tiles; ++bx) {
        entries.push_back(
            {static_cast<std::uint32_t>(by * blocks_wide_ + bx), kind, static_cast<std::uint32_t>(index)});
      }
    }
  };
  for (std::size_t i = 0; i < features.nodes.size(); ++i) {
    PixelBox box;
    box.extend(features.nodes[i].at);
    add(box, 0, kNode, i);
  }
  for (std::size_t i = 0; i < features.lines.size(); ++i) {
    const auto& line = features.lines[i];
    add(line.box, line.group == osm::kRoad ? halo_px : 0, kLine, i);
  }
  for (std::size_t i = 0; i < features.areas.size(); ++i) add(features.areas[i].box, 0, kArea, i);
  std::sort(entries.begin(), entries.end());

  fd_ = core::open_unlinked_file(spill_dir, ".seqloc-features");
  if (fd_ < 0) {
    throw IoError("cannot create the features' spill file in " + spill_dir.string() + ": " + std::strerror(errno));
  }
  try {
    spill(features, entries, block_count);
  } catch (...) {
    ::close(fd_);  // the destructor does not run for a constructor that throws
    throw;
  }
}

void FeatureBlocks::spill(const raster::RegionFeatures& features, const std::vector<Entry>& entries,
                          std::size_t block_count) {
  offsets_.assign(block_count + 1, 0);
  Writer out;
  auto it = entries.begin();
  for (std::size_t block = 0; block < block_count; ++block) {
    offsets_[block] = spilled_ + out.size();
    for (const Kind kind : {kNode, kLine, kArea}) {
      auto end = it;
      while (end != entries.end() && end->block == block && end->kind == kind) ++end;
      out.put(static_cast<std::uint32_t>(end - it));
      for (; it != end; ++it) {
        if (kind == kNode) {
          out.put(features.nodes[it->index]);
        } else if (kind == kLine) {
          out.put(features.lines[it->index].group);
          out.put_pixels(features.lines[it->index].points);
        } else {
          const auto& area = features.areas[it->index];
          out.put(area.group);
          out.put(static_cast<std::uint32_t>(area.rings.size()));
          for (const auto& ring : area.rings) out.put_pixels(ring);
        }
      }
    }
    if (out.size() > (std::size_t{8} << 20)) {
      spilled_ += out.size();
      out.flush(fd_, dir_);
    }
  }
  spilled_ += out.size();
  out.flush(fd_, dir_);
  offsets_[block_count] = spilled_;
}

FeatureBlocks::~FeatureBlocks() {
  if (fd_ >= 0) ::close(fd_);
}

RegionGrid FeatureBlocks::block_grid(std::int64_t bx, std::int64_t by) const {
  RegionGrid g = grid_;
  g.tx0 = grid_.tx0 + bx * block_tiles_;
  g.tx1 = std::min(grid_.tx1, g.tx0 + block_tiles_);
  g.ty1 = grid_.ty1 - by * block_tiles_;
  g.ty0 = std::max(grid_.ty0, g.ty1 - block_tiles_);
  return g;
}

raster::RegionFeatures FeatureBlocks::load(std::int64_t bx, std::int64_t by) const {
  const auto block = static_cast<std::size_t>(by * blocks_wide_ + bx);
  const std::uint64_t begin = offsets_[block], size = offsets_[block + 1] - begin;
  std::vector<char> bytes(size);
  std::size_t done = 0;
  while (done < size) {
    const ssize_t n = ::pread(fd_, bytes.data() + done, size - done, static_cast<off_t>(begin + done));
    if (n < 0 && errno == EINTR) continue;
    if (n <= 0) {
      throw IoError("cannot read back the features' spill file in " + dir_.string() + ": " +
                    std::strerror(n < 0 ? errno : EIO));
    }
    done += static_cast<std::size_t>(n);
  }
  Reader in(std::move(bytes));
  raster::RegionFeatures features;
  features.nodes.resize(in.get<std::uint32_t>());
  for (auto& node : features.nodes) node = in.get<PixelNode>();
  features.lines.resize(in.get<std::uint32_t>());
  for (auto& line : features.lines) {
    line.group = in.get<osm::Group>();
    line.points = in.get_pixels(line.box);
  }
  features.areas.resize(in.get<std::uint32_t>());
  for (auto& area : features.areas) {
    area.group = in.get<osm::Group>();
    area.rings.resize(in.get<std::uint32_t>());
    for (auto& ring : area.rings) ring = in.get_pixels(area.box);
  }
  return features;
}

}  // namespace seqloc::ingest::detail
