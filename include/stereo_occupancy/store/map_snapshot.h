#pragma once
/// @file
/// The live map's whole-map outputs kept tile by tile (the octree's binary
/// and full data, the occupied cells' centres, the projection), so that
/// they cost what changed: only the tiles changed since the last apply()
/// are encoded again, from copies of their leaves, and building a message
/// needs the map not at all. The accumulator copies the leaves under its
/// lock and does the rest outside it.

#include <octomap/OcTree.h>

#include <cstdint>
#include <functional>
#include <map>
#include <ostream>
#include <string>
#include <vector>

#include "stereo_occupancy/map_accumulator.h"
#include "stereo_occupancy/projected_map.h"
#include "stereo_occupancy/store/tile_store.h"

namespace stereo_occupancy {

/// A tile's content as MissionMap::takeChangedTiles() hands it out; no leaves: the tile is gone.
struct TileContent {
  MapAccumulator::TileIndex tile;
  std::vector<MapAccumulator::Leaf> leaves;
};

/// What a MapSnapshot builds its outputs with.
struct MapSnapshotConfig {
  double resolution_m = 0.25;             ///< the map's cell edge [m]
  double occupancy_threshold_prob = 0.5;  ///< cells at or above it are occupied
  double projection_min_z_m = -10000.0;   ///< the projection's height band [m]
  double projection_max_z_m = 10000.0;
};

/// The whole-map outputs of a map, per tile. Not thread-safe.
class MapSnapshot {
 public:
  explicit MapSnapshot(const MapSnapshotConfig& config);
  /// Keep the full (log-odds) data too (octomap_full has a subscriber); it
  /// costs about 5 bytes a node. Switched on, the next apply() must be the
  /// whole map; switched off, the data goes.
  void setKeepFull(bool keep);
  /// True until an apply() of the whole map, and after setKeepFull(true) switched it on.
  bool needsWholeMap() const { return needs_whole_map_; }
  /// Replaces each tile of @p changes by its content (no leaves: removes it);
  /// @p whole_map: they are the whole map, every other tile goes.
  void apply(const std::vector<TileContent>& changes, bool whole_map);
  /// What OcTree::writeBinaryData (@p binary) or writeData writes for the
  /// map, byte for byte. @throws std::logic_error for full data not kept.
  void writeData(bool binary, std::ostream& out) const;
  /// At least the size of what writeData(@p binary) writes [bytes].
  size_t dataBytesBound(bool binary) const;
  /// The occupied leaves: how many, and each one's centre.
  size_t numOccupied() const;
  void forEachOccupiedCentre(const std::function<void(const octomap::point3d&)>& f) const;
  /// projectOccupancy() of the map.
  ProjectedMap projection() const;
  size_t numTiles() const { return tiles_.size(); }
  double resolution() const { return config_.resolution_m; }

 private:
  struct Tile {
    TileRow row;                             ///< the tile's summary, as the tree writer needs it
    std::string binary, full;                ///< the tile's subtree, encoded
    std::vector<octomap::point3d> occupied;  ///< occupied leaves' centres
    std::vector<ProjectedLeaf> projected;    ///< columns in the height band
  };
  Tile encode(const TileContent& content) const;

  MapSnapshotConfig config_;
  bool keep_full_ = false;
  bool needs_whole_map_ = true;
  std::map<uint64_t, Tile> tiles_;  ///< by TileStore::pack
};

}  // namespace stereo_occupancy
