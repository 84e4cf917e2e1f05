// Merging the shards of a sharded build into one region cache.
#include "seqloc/raster/cache.hpp"

#include <set>

#include "cache_format.hpp"
#include "sqlite.hpp"

namespace seqloc::raster {

void merge_shards(const std::vector<std::filesystem::path>& shards, const std::filesystem::path& out) {
  if (shards.empty()) throw CacheError("cache merge: no shards given");
  std::vector<CacheMetadata> metas;
  for (const auto& shard : shards) {
    metas.push_back(read_cache_metadata(shard));
    if (!metas.back().complete) throw CacheFormatError(shard.string() + ": shard is unfinished; rerun its build");
  }
  const CacheMetadata& first = metas.front();
  std::set<int> seen;
  for (std::size_t i = 0; i < metas.size(); ++i) {
    if (!metas[i].same_build(first) || metas[i].shard_count != first.shard_count) {
      throw CacheError(shards[i].string() + ": belongs to another build than " + shards[0].string() +
                       " (source, bbox, clamp or shard count differ)");
    }
    if (!seen.insert(metas[i].shard_index).second) {
      throw CacheError(shards[i].string() + ": shard " + std::to_string(metas[i].shard_index) + " given twice");
    }
  }
  if (static_cast<int>(seen.size()) != first.shard_count) {
    for (int i = 0; i < first.shard_count; ++i) {
      if (!seen.count(i)) {
        throw CacheError("cache merge: shard " + std::to_string(i) + "/" + std::to_string(first.shard_count) +
                         " is missing");
      }
    }
  }
  CacheMetadata merged = first;
  merged.shard_index = 0;
  merged.shard_count = 1;
  merged.created_utc.clear();
  CacheWriter writer(out, merged);
  for (std::size_t i = 0; i < shards.size(); ++i) {
    detail::Database db(shards[i].string(), SQLITE_OPEN_READONLY);
    if (i == 0) {
      std::vector<RoadLine> roads;
      detail::Statement s(db, "SELECT geom, osm_id, highway FROM roads ORDER BY fid");
      while (s.step()) {
        roads.push_back({s.column_int(1), s.column_text(2), detail::parse_linestring_blob(s.column_blob(0), shards[i].string())});
      }
      writer.write_roads(roads);
    }
    // Classes may be left out of a corridor cache's tiles, road distances never are.
    detail::Statement s(db, "SELECT d.tile_column, d.tile_row, c.tile_data, d.tile_data, a.min, a.max, a.mean "
                            "FROM road_distance d LEFT JOIN classes c ON c.tile_column = d.tile_column AND "
                            "c.tile_row = d.tile_row LEFT JOIN gpkg_2d_gridded_tile_ancillary a ON "
                            "a.tpudt_name = 'road_distance' AND a.tpudt_id = d.id");
    while (s.step()) {
      EncodedTile tile;
      tile.col = s.column_int(0);
      tile.row = s.column_int(1);
      if (!metas[i].shard_owns(tile.col, tile.row)) {
        throw CacheError(shards[i].string() + ": holds tile (" + std::to_string(tile.col) + ", " +
                         std::to_string(tile.row) + ") of another shard");
      }
      const auto c = s.column_blob(2);
      const auto d = s.column_blob(3);
      tile.classes_png.assign(c.begin(), c.end());
      tile.distance_png.assign(d.begin(), d.end());
      tile.distance_min_m = s.column_double(4);
      tile.distance_max_m = s.column_double(5);
      tile.distance_mean_m = s.column_double(6);
      writer.write_tile(tile);
    }
  }
  writer.finish();
}

}  // namespace seqloc::raster
