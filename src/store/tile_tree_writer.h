#pragma once
/// @file
/// The store library's one writer of whole octrees from tiles: the nodes
/// above the tiles in octomap's pre-order, each tile's subtree from its
/// source. What OcTree::writeData (full) or writeBinaryData writes for the
/// tree of all the tiles, byte for byte, without building that tree.

#include <array>
#include <functional>
#include <ostream>
#include <vector>

#include <octomap/OcTree.h>

#include "stereo_occupancy/store/tile_store.h"

namespace stereo_occupancy {

class TileTreeWriter {
 public:
  /// Writes @p row's subtree (the tile's node and all below) as @p full asks.
  using WriteTile = std::function<void(const TileRow& row, std::ostream& out)>;
  /// @param threshold_log the occupancy threshold in log-odds, for the binary
  /// codes of tiles that are one leaf.
  TileTreeWriter(std::vector<TileRow> rows, bool full, float threshold_log, WriteTile write_tile);
  /// Nodes of the whole tree (0 without tiles).
  size_t numNodes() const;
  /// The tree's data; the caller writes any file header.
  void writeData(std::ostream& out) const;

 private:
  std::vector<size_t> allRows() const;  ///< 0 .. rows_.size() - 1
  std::array<std::vector<size_t>, 8> split(unsigned depth, const std::vector<size_t>& rows) const;
  size_t countNodes(unsigned depth, const std::vector<size_t>& rows) const;
  void writeNode(unsigned depth, const std::vector<size_t>& rows, std::ostream& out) const;

  std::vector<TileRow> rows_;
  bool full_;
  float threshold_log_;
  WriteTile write_tile_;
};

/// The node at depth kTileDepth of a tree that holds one tile (TileStore rows, MapSnapshot).
const octomap::OcTreeNode* tileNode(const octomap::OcTree& tree);

/// The occupancy threshold @p prob in log-odds as an OcTree keeps it.
float thresholdLog(double resolution_m, double prob);

}  // namespace stereo_occupancy
