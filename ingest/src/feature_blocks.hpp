#pragma once
// The region's features cut into square blocks of tiles and kept in an unnamed temporary file, so
// that rendering holds one block's features and bins at a time, whatever the region's area.
//
// A feature is stored with every block that one of its tiles' bins would name: nodes, lines and
// areas whose pixel box meets the block, roads whose box grown by the distance halo meets it.
// A block's TileRenderer therefore sees, tile for tile, the features the region's would see, and
// since every primitive is drawn on the global lattice its tiles are identical.

#include <cstdint>
#include <filesystem>
#include <vector>

#include "seqloc/raster/grid.hpp"
#include "seqloc/raster/tile_renderer.hpp"

namespace seqloc::ingest::detail {

class FeatureBlocks {
 public:
  /// Cuts `features` (which may be freed afterwards) over `grid` into blocks of `block_tiles` x
  /// `block_tiles` tiles, spilled to an unnamed file in `spill_dir`. Throws std::runtime_error
  /// naming the directory when the file cannot be created or written.
  FeatureBlocks(const raster::RegionFeatures& features, const raster::RegionGrid& grid, int halo_px, int block_tiles,
                const std::filesystem::path& spill_dir);
  ~FeatureBlocks();
  FeatureBlocks(const FeatureBlocks&) = delete;
  FeatureBlocks& operator=(const FeatureBlocks&) = delete;

  [[nodiscard]] std::int64_t blocks_wide() const { return blocks_wide_; }
  [[nodiscard]] std::int64_t blocks_high() const { return blocks_high_; }
  /// The sub-grid of block (bx, by); by counts from the north, as GeoPackage rows do.
  [[nodiscard]] raster::RegionGrid block_grid(std::int64_t bx, std::int64_t by) const;
  /// The block's features, read back from the spill file.
  [[nodiscard]] raster::RegionFeatures load(std::int64_t bx, std::int64_t by) const;
  /// Bytes written to the spill file (features stored once per block they meet).
  [[nodiscard]] std::uint64_t spilled_bytes() const { return spilled_; }

 private:
  struct Entry;
  void spill(const raster::RegionFeatures& features, const std::vector<Entry>& entries, std::size_t block_count);

  raster::RegionGrid grid_;
  int block_tiles_;
  std::int64_t blocks_wide_ = 0, blocks_high_ = 0;
  int fd_ = -1;
  std::filesystem::path dir_;
  std::vector<std::uint64_t> offsets_;  ///< per block, plus one past the end
  std::uint64_t spilled_ = 0;
};

}  // namespace seqloc::ingest::detail
