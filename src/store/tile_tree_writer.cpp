#include "tile_tree_writer.h"

#include <octomap/OcTree.h>

#include <algorithm>
#include <limits>

namespace stereo_occupancy {

namespace {
/// Child index (octomap::computeChildIdx) of @p row's tile at node depth @p depth.
unsigned childOf(const TileRow& row, unsigned depth) {
  unsigned idx = 0;
  for (int a = 0; a < 3; ++a) {
    const unsigned key = static_cast<unsigned>(row.tile[a] + (1 << MapAccumulator::kTileDepth) / 2);
    if (key & (1u << (MapAccumulator::kTileDepth - 1 - depth))) idx |= 1u << a;
  }
  return idx;
}
}  // namespace

const octomap::OcTreeNode* tileNode(const octomap::OcTree& tree) {
  const octomap::OcTreeNode* node = tree.getRoot();
  for (unsigned d = 0; d < MapAccumulator::kTileDepth; ++d)
    for (unsigned c = 0; c < 8; ++c)
      if (tree.nodeChildExists(node, c)) {
        node = tree.getNodeChild(node, c);
        break;
      }
  return node;
}

float thresholdLog(double resolution_m, double prob) {
  octomap::OcTree probe(resolution_m);
  probe.setOccupancyThres(prob);
  return probe.getOccupancyThresLog();
}

TileTreeWriter::TileTreeWriter(std::vector<TileRow> rows, bool full, float threshold_log, WriteTile write_tile)
    : rows_(std::move(rows)), full_(full), threshold_log_(threshold_log), write_tile_(std::move(write_tile)) {}

std::array<std::vector<size_t>, 8> TileTreeWriter::split(unsigned depth, const std::vector<size_t>& rows) const {
  std::array<std::vector<size_t>, 8> children;
  for (size_t i : rows) children[childOf(rows_[i], depth)].push_back(i);
  return children;
}

std::vector<size_t> TileTreeWriter::allRows() const {
  std::vector<size_t> all(rows_.size());
  for (size_t i = 0; i < all.size(); ++i) all[i] = i;
  return all;
}

size_t TileTreeWriter::numNodes() const { return rows_.empty() ? 0 : countNodes(0, allRows()); }

size_t TileTreeWriter::countNodes(unsigned depth, const std::vector<size_t>& rows) const {
  if (depth == MapAccumulator::kTileDepth) return rows_[rows.front()].nodes;
  size_t n = 1;
  for (const auto& child : split(depth, rows))
    if (!child.empty()) n += countNodes(depth + 1, child);
  return n;
}

void TileTreeWriter::writeData(std::ostream& out) const {
  if (!rows_.empty()) writeNode(0, allRows(), out);
}

void TileTreeWriter::writeNode(unsigned depth, const std::vector<size_t>& rows, std::ostream& out) const {
  if (depth == MapAccumulator::kTileDepth) return write_tile_(rows_[rows.front()], out);
  const auto children = split(depth, rows);
  if (full_) {
    // An inner node's value is its children's largest (updateInnerOccupancy).
    float value = -std::numeric_limits<float>::max();
    for (size_t i : rows) value = std::max(value, rows_[i].max_log_odds);
    out.write(reinterpret_cast<const char*>(&value), sizeof value);
    char bits = 0;
    for (unsigned c = 0; c < 8; ++c)
      if (!children[c].empty()) bits = static_cast<char>(bits | (1 << c));
    out.write(&bits, 1);
  } else {
    // OccupancyOcTreeBase::writeBinaryNode's two bits per child: 11 inner, 01 occupied, 10 free, 00 unknown.
    uint16_t bits = 0;
    for (unsigned c = 0; c < 8; ++c) {
      if (children[c].empty()) continue;
      const TileRow& first = rows_[children[c].front()];
      const bool leaf = depth + 1 == MapAccumulator::kTileDepth && first.nodes == 1;
      const unsigned code = !leaf ? 3u : first.max_log_odds >= threshold_log_ ? 2u : 1u;
      bits = static_cast<uint16_t>(bits | (code << (2 * c)));
    }
    const char bytes[2] = {static_cast<char>(bits & 0xff), static_cast<char>(bits >> 8)};
    out.write(bytes, 2);
  }
  for (const auto& child : children)
    if (!child.empty()) writeNode(depth + 1, child, out);
}

}  // namespace stereo_occupancy
