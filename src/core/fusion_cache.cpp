#include "stereo_occupancy/fusion_cache.h"

#include <algorithm>
#include <limits>
#include <mutex>

namespace stereo_occupancy {

namespace {

constexpr int kEdgeBits = 16 - AccumulatingOcTree::kPartDepth;
constexpr float kNoLeaf = std::numeric_limits<float>::quiet_NaN();
/// add()'s row outputs kept beyond an update's: more than kKeptRowsFactor
/// times its rows and kKeptRows are let go.
constexpr size_t kKeptRowsFactor = 4, kKeptRows = 256;

/// A block's key in the map: its lowest key / kEdge, 16 bits per axis.
uint64_t blockKey(const octomap::OcTreeKey& first) {
  return (uint64_t{first[0]} >> kEdgeBits) | ((uint64_t{first[1]} >> kEdgeBits) << 16) |
         ((uint64_t{first[2]} >> kEdgeBits) << 32);
}

/// How many updates after kMinUnwrittenUpdates the block whose lowest key is
/// @p first falls due: 0 .. kStaggerUpdates - 1, from a hash of its key
/// (neighbouring blocks differ), the same for any number of threads.
size_t staggerOf(const octomap::OcTreeKey& first) {
  constexpr int kStaggerBits = 3;
  static_assert(FusionCache::kStaggerUpdates == size_t{1} << kStaggerBits, "the hash's top bits");
  constexpr uint64_t kGoldenRatio = 0x9E3779B97F4A7C15ull;  // Fibonacci hashing: the top bits mix all the key's
  return static_cast<size_t>((blockKey(first) * kGoldenRatio) >> (64 - kStaggerBits));
}

/// The clamping and occupancy thresholds of the tree a stretch updates.
struct Thresholds {
  float lo, hi;    ///< clamping [log-odds]
  float occupied;  ///< classOfLogOdds()'s
};

/// Cells @p cells[c] of a stretch (of one block's row) updated by @p u[c],
/// c in [0, n): OccupancyOcTreeBase::updateNodeLogOdds() (a new leaf starts
/// at 0) with updateNode's early return (a leaf clamped the way of the
/// update takes none). Bit c of the result: cell c changed; of
/// @p class_changed (null: not asked): its class changed too (a new leaf's
/// always does).
uint32_t updateStretch(const float* u, float* cells, int n, const Thresholds& t, uint32_t* class_changed) {
  static_assert(FusionCache::kEdge <= 32, "a stretch's cells are the bits of a 32-bit mask");
  uint32_t taken = 0;
  for (int c = 0; c < n; ++c) {
    const float old = cells[c];
    const bool created = !(old == old);
    if (!created && ((u[c] >= 0.0f && old >= t.hi) || (u[c] <= 0.0f && old <= t.lo))) continue;
    float value = (created ? 0.0f : old) + u[c];
    if (value < t.lo)
      value = t.lo;
    else if (value > t.hi)
      value = t.hi;
    cells[c] = value;
    taken |= uint32_t{1} << c;
    if (class_changed && (created || classOfLogOdds(old, t.occupied) != classOfLogOdds(value, t.occupied)))
      *class_changed |= uint32_t{1} << c;
  }
  return taken;
}

/// Sets the cube of @p edge cells at @p offset (a block's linear index) to @p value.
void fillCube(float* cells, int offset, int edge, float value) {
  for (int z = 0; z < edge; ++z)
    for (int y = 0; y < edge; ++y) {
      float* row = cells + offset + FusionCache::kEdge * (y + FusionCache::kEdge * z);
      std::fill(row, row + edge, value);
    }
}

/// The values of @p node's leaves into the cube of @p edge cells at @p offset.
void readNode(const AccumulatingOcTree& tree, const octomap::OcTreeNode* node, int offset, int edge, float* cells) {
  if (!tree.nodeHasChildren(node)) return fillCube(cells, offset, edge, node->getLogOdds());
  const int half = edge / 2;
  for (unsigned i = 0; i < 8; ++i) {
    if (!tree.nodeChildExists(node, i)) continue;  // no leaf: the NaN stays
    const int child = offset + (i & 1 ? half : 0) + (i & 2 ? half * FusionCache::kEdge : 0) +
                      (i & 4 ? half * FusionCache::kEdge * FusionCache::kEdge : 0);
    readNode(tree, tree.getNodeChild(node, i), child, half, cells);
  }
}

}  // namespace

void FusionCache::read(const AccumulatingOcTree& tree, Block* b) {
  b->log_odds.fill(kNoLeaf);
  const octomap::OcTreeNode* node = tree.getRoot();
  const int leaf_depth = static_cast<int>(tree.getTreeDepth());
  // The walk of LeafUpdater::descend(): a node without children on the way
  // is a (pruned) leaf whose value every cell below it has.
  for (int d = 0; node && d < AccumulatingOcTree::kPartDepth; ++d) {
    if (!tree.nodeHasChildren(node)) return b->log_odds.fill(node->getLogOdds());
    const unsigned pos = octomap::computeChildIdx(b->first, leaf_depth - 1 - d);
    node = tree.nodeChildExists(node, pos) ? tree.getNodeChild(node, pos) : nullptr;
  }
  if (node) readNode(tree, node, 0, kEdge, b->log_odds.data());
}

FusionCache::Block* FusionCache::blockAt(const octomap::OcTreeKey& first, const AccumulatingOcTree& tree) {
  Block* b = nullptr;
  {
    // Workers look blocks up at once; each block is one worker's (its row of blocks).
    std::lock_guard<std::mutex> lock(blocks_mutex_);
    std::unique_ptr<Block>& slot = blocks_[blockKey(first)];
    if (slot) return slot.get();
    slot = std::make_unique<Block>();
    b = slot.get();
  }
  b->first = first;
  b->changed.fill(0);
  read(tree, b);  // the tree is only read while updates are added
  return b;
}

/// What one row of blocks of an update gave: kept from update to update for their memory.
struct FusionCache::RowOutput {
  std::vector<CellClassChange> changes;
  std::vector<Eigen::Vector3i> touched;
  std::vector<Block*> blocks;  ///< the row's blocks by x (null: not looked up yet)
  bool overflowed = false;
};

FusionCache::FusionCache() = default;
FusionCache::~FusionCache() = default;

size_t FusionCache::add(const GridUpdateView& update, AccumulatingOcTree* tree, int key_offset, ClassChangeLog* log,
                        std::vector<Eigen::Vector3i>* touched_blocks, WorkerPool* pool,
                        AccumulatingOcTree::WorkerCounters* counters) {
  ++updates_;
  touched_blocks->clear();
  if (update.log_odds.empty()) return 0;  // no cells (an empty box may carry empty runs)
  // Rows of blocks (a block's edge of y and of z, the whole x range) hold
  // blocks no other row holds: each row that holds a cell is one task, in z
  // then y order, and the tasks' class changes and blocks follow in that
  // order whatever the threads. The rows come from the runs, so work and
  // memory follow the cells carried, not the box claimed.
  const Eigen::Vector3i key_first = update.origin_index + Eigen::Vector3i::Constant(key_offset);
  const Eigen::Vector3i key_last = key_first + update.size - Eigen::Vector3i::Ones();
  const int by0 = key_first.y() >> kEdgeBits, bz0 = key_first.z() >> kEdgeBits;
  const int64_t rows_y = (key_last.y() >> kEdgeBits) - by0 + 1;
  const int64_t nx = update.size.x(), ny = update.size.y();
  const int64_t blocks_x = (key_last.x() >> kEdgeBits) - (key_first.x() >> kEdgeBits) + 1;
  rows_of_blocks_.clear();
  for (size_t r = 0; r < update.run_start.size(); ++r) {
    if (update.run_length[r] == 0) continue;
    // The grid rows (y, z) the run covers, each once, with its cells in each.
    const int64_t run_first = update.run_start[r], run_end = run_first + update.run_length[r];
    for (int64_t row = run_first / nx; row <= (run_end - 1) / nx; ++row) {
      const int64_t by = ((row % ny + key_first.y()) >> kEdgeBits) - by0;
      const int64_t bz = ((row / ny + key_first.z()) >> kEdgeBits) - bz0;
      const int64_t id = bz * rows_y + by;
      const int64_t cells = std::min(run_end, (row + 1) * nx) - std::max(run_first, row * nx);
      if (rows_of_blocks_.empty() || rows_of_blocks_.back().id != id)
        rows_of_blocks_.push_back(RowOfBlocks{id, cells});
      else
        rows_of_blocks_.back().cells += cells;
    }
  }
  std::sort(rows_of_blocks_.begin(), rows_of_blocks_.end(),
            [](const RowOfBlocks& a, const RowOfBlocks& b) { return a.id < b.id; });
  size_t rows = 0;  // equal ids merged
  for (const RowOfBlocks& row : rows_of_blocks_) {
    if (rows > 0 && rows_of_blocks_[rows - 1].id == row.id)
      rows_of_blocks_[rows - 1].cells += row.cells;
    else
      rows_of_blocks_[rows++] = row;
  }
  rows_of_blocks_.resize(rows);
  if (rows_.size() < rows) rows_.resize(rows);
  // A rare update with many more rows than the next leaves their memory behind: let it go.
  if (rows_.size() > kKeptRowsFactor * rows + kKeptRows) rows_.resize(rows);
  for (size_t r = 0; r < rows; ++r) {
    if (!rows_[r]) rows_[r] = std::make_unique<RowOutput>();
    rows_[r]->changes.clear();
    rows_[r]->touched.clear();
    rows_[r]->overflowed = false;
  }
  value_start_.resize(update.run_start.size() + 1);
  value_start_[0] = 0;
  for (size_t r = 0; r < update.run_start.size(); ++r) value_start_[r + 1] = value_start_[r] + update.run_length[r];
  const size_t max_changes = log ? log->max_changes - std::min(log->max_changes, log->changes.size()) : 0;
  auto addRow = [&](size_t row, unsigned) {
    const int by = by0 + static_cast<int>(rows_of_blocks_[row].id % rows_y);
    const int bz = bz0 + static_cast<int>(rows_of_blocks_[row].id / rows_y);
    // The row's local y and z ranges, inside the update's box.
    const int64_t y0 = std::max(by << kEdgeBits, key_first.y()) - key_first.y();
    const int64_t y1 = std::min((by + 1) << kEdgeBits, key_last.y() + 1) - key_first.y();
    const int64_t z0 = std::max(bz << kEdgeBits, key_first.z()) - key_first.z();
    const int64_t z1 = std::min((bz + 1) << kEdgeBits, key_last.z() + 1) - key_first.z();
    addRowOfBlocks(update, *tree, key_offset, y0, y1, z0, z1, log != nullptr, max_changes, rows_[row].get());
  };
  // The most blocks a row can add: one per cell, one per block along x.
  auto newBlocksAtMost = [&](size_t row) {
    return static_cast<size_t>(std::min(rows_of_blocks_[row].cells, blocks_x));
  };
  // In batches of rows that keep the blocks within kMaxBlocks (a sparse
  // update spread over a huge box would need a block per cell): when the
  // next row might pass it, every block is written back and let go first.
  // An update's usual rows are one batch (docs/performance.md: the flights'
  // blocks held and new ones stay far below the bound).
  size_t written = 0;
  for (size_t first = 0; first < rows;) {
    if (blocks_.size() + newBlocksAtMost(first) > kMaxBlocks) {
      written += writeBackIf(tree, pool, counters, [](const Block&) { return true; });
      clear();
    }
    size_t end = first + 1, room = kMaxBlocks - std::min(kMaxBlocks, blocks_.size() + newBlocksAtMost(first));
    for (; end < rows && newBlocksAtMost(end) <= room; ++end) room -= newBlocksAtMost(end);
    if (pool && end - first > 1)
      pool->run(end - first, [&](size_t k, unsigned worker) { addRow(first + k, worker); });
    else
      for (size_t r = first; r < end; ++r) addRow(r, 0);
    first = end;
  }
  for (size_t r = 0; r < rows; ++r) {
    const RowOutput& out = *rows_[r];
    touched_blocks->insert(touched_blocks->end(), out.touched.begin(), out.touched.end());
    if (!log || log->overflowed) continue;
    if (out.overflowed || log->changes.size() + out.changes.size() > log->max_changes) {
      log->overflowed = true;
      continue;
    }
    log->changes.insert(log->changes.end(), out.changes.begin(), out.changes.end());
  }
  return written;
}

void FusionCache::addRowOfBlocks(const GridUpdateView& update, const AccumulatingOcTree& tree, int key_offset,
                                 int64_t y0, int64_t y1, int64_t z0, int64_t z1, bool record, size_t max_changes,
                                 RowOutput* out) {
  const Thresholds thresholds{tree.getClampingThresMinLog(), tree.getClampingThresMaxLog(),
                              tree.getOccupancyThresLog()};
  const int64_t nx = update.size.x(), ny = update.size.y();
  const int bx0 = (update.origin_index.x() + key_offset) >> kEdgeBits;
  const int nbx = ((update.origin_index.x() + update.size.x() - 1 + key_offset) >> kEdgeBits) - bx0 + 1;
  out->blocks.assign(static_cast<size_t>(nbx), nullptr);
  Block* block = nullptr;
  int block_x = -1;  // block's index in out->blocks
  for (int64_t z = z0; z < z1; ++z) {
    // The plane's stretch of the row: linear indices [from, to).
    const int64_t from = (z * ny + y0) * nx, to = (z * ny + y1) * nx;
    const auto key_z = static_cast<octomap::key_type>(z + update.origin_index.z() + key_offset);
    const int cz = key_z & (kEdge - 1);
    // The first run that ends after from.
    size_t r = static_cast<size_t>(
        std::upper_bound(update.run_start.begin(), update.run_start.end(), static_cast<uint32_t>(from)) -
        update.run_start.begin());
    if (r > 0 && update.run_start[r - 1] + update.run_length[r - 1] > from) --r;
    for (; r < update.run_start.size() && update.run_start[r] < to; ++r) {
      int64_t i = std::max<int64_t>(update.run_start[r], from);
      const int64_t end = std::min<int64_t>(int64_t{update.run_start[r]} + update.run_length[r], to);
      size_t v = value_start_[r] + static_cast<size_t>(i - update.run_start[r]);
      int64_t x = i % nx, y = (i / nx) % ny;  // then step by step along the run
      while (i < end) {
        // A row's stretch inside one block.
        const octomap::OcTreeKey key(static_cast<octomap::key_type>(x + update.origin_index.x() + key_offset),
                                     static_cast<octomap::key_type>(y + update.origin_index.y() + key_offset), key_z);
        const int cx = key[0] & (kEdge - 1), cy = key[1] & (kEdge - 1);
        const int64_t stretch = std::min<int64_t>({end - i, kEdge - cx, nx - x});
        const int bx = (key[0] >> kEdgeBits) - bx0;
        if (bx != block_x) {
          // The row's blocks are looked up once each: its rows pass through them again and again.
          Block*& known = out->blocks[static_cast<size_t>(bx)];
          if (!known) {  // the block's first cell of this update
            const octomap::OcTreeKey first(static_cast<octomap::key_type>(key[0] - cx),
                                           static_cast<octomap::key_type>(key[1] - cy),
                                           static_cast<octomap::key_type>(key[2] - cz));
            known = blockAt(first, tree);
            known->last_update = updates_;
            // Exact divisions: the key offset is a multiple of kEdge.
            out->touched.emplace_back((first[0] - key_offset) / kEdge, (first[1] - key_offset) / kEdge,
                                      (first[2] - key_offset) / kEdge);
          }
          block = known;
          block_x = bx;
        }
        // The stretch's cells are one row of the block: their changed bits
        // lie in one word (kEdge divides 64).
        const int base = cx + kEdge * (cy + kEdge * cz);
        float* const cells = block->log_odds.data() + base;
        uint32_t class_changed = 0;
        const uint32_t taken = updateStretch(&update.log_odds[v], cells, static_cast<int>(stretch), thresholds,
                                             record ? &class_changed : nullptr);
        block->changed[static_cast<size_t>(base) >> 6] |= uint64_t{taken} << (base & 63);
        const bool changed_any = taken != 0;
        for (uint32_t bits = class_changed; bits != 0; bits &= bits - 1) {
          const int c = __builtin_ctz(bits);
          if (out->changes.size() >= max_changes) {
            out->overflowed = true;
            continue;
          }
          out->changes.push_back(
              CellClassChange{Eigen::Vector3i(key[0] + c - key_offset, key[1] - key_offset, key[2] - key_offset),
                              classOfLogOdds(cells[c], thresholds.occupied)});
        }
        if (changed_any && !block->unwritten) {
          block->unwritten = true;
          block->write_due = updates_ + kMinUnwrittenUpdates + staggerOf(block->first);
        }
        v += static_cast<size_t>(stretch);
        i += stretch;
        x += stretch;
        if (x == nx) {  // the run goes on in the next row of the plane
          x = 0;
          ++y;
        }
      }
    }
  }
}

size_t FusionCache::gatherChanged(Block* b, std::vector<AccumulatingOcTree::SiblingBlock>* part) {
  // Each block's changed cells as sibling blocks (NaN: not changed), in the tree's child order.
  part->clear();
  size_t cells = 0;
  auto rowBits = [b](int y, int z) {  // the changed bits of the row (y, z): kEdge of them
    const int row = y + kEdge * z;
    return static_cast<unsigned>(b->changed[static_cast<size_t>(row) / 4] >> (16 * (row % 4))) & 0xffffu;
  };
  static_assert(kEdge == 16, "a row's changed bits are a quarter of a word");
  for (int z = 0; z < kEdge; z += 2)
    for (int y = 0; y < kEdge; y += 2) {
      const unsigned rows[4] = {rowBits(y, z), rowBits(y + 1, z), rowBits(y, z + 1), rowBits(y + 1, z + 1)};
      const unsigned any_row = rows[0] | rows[1] | rows[2] | rows[3];
      if (any_row == 0) continue;
      for (int x = 0; x < kEdge; x += 2) {
        if (((any_row >> x) & 3u) == 0) continue;
        AccumulatingOcTree::SiblingBlock s;
        for (int i = 0; i < 8; ++i) {
          const int dx = i & 1, row = i >> 1;  // child i: (x + dx, y + (i >> 1 & 1), z + (i >> 2))
          const bool changed = (rows[row] >> (x + dx)) & 1u;
          const int cell = (x + dx) + kEdge * ((y + (row & 1)) + kEdge * (z + (row >> 1)));
          s.values[i] = changed ? b->log_odds[static_cast<size_t>(cell)] : kNoLeaf;
          cells += changed;
        }
        s.first = octomap::OcTreeKey(static_cast<octomap::key_type>(b->first[0] + x),
                                     static_cast<octomap::key_type>(b->first[1] + y),
                                     static_cast<octomap::key_type>(b->first[2] + z));
        part->push_back(s);
      }
    }
  b->changed.fill(0);
  b->unwritten = false;
  return cells;
}

template <typename Due>
size_t FusionCache::writeBackIf(AccumulatingOcTree* tree, WorkerPool* pool,
                                AccumulatingOcTree::WorkerCounters* counters, Due due) {
  due_.clear();
  for (auto& entry : blocks_)
    if (entry.second->unwritten && due(*entry.second)) due_.push_back(entry.second.get());
  const size_t used = due_.size();
  if (parts_.size() < used) parts_.resize(used);
  part_cells_.assign(used, 0);
  auto gather = [this](size_t p, unsigned) { part_cells_[p] = gatherChanged(due_[p], &parts_[p]); };
  if (pool && used > 1)
    pool->run(used, gather);
  else
    for (size_t p = 0; p < used; ++p) gather(p, 0);
  size_t cells = 0;
  for (size_t n : part_cells_) cells += n;
  if (used == 0) return 0;
  std::vector<const std::vector<AccumulatingOcTree::SiblingBlock>*> parts;
  for (size_t p = 0; p < used; ++p) parts.push_back(&parts_[p]);
  if (pool) {
    tree->addSiblingsInParts(parts, pool, counters, nullptr, /*set_values=*/true);
  } else {
    AccumulatingOcTree::LeafUpdater updater(tree);
    updater.setValues();
    for (const auto* part : parts)
      for (const AccumulatingOcTree::SiblingBlock& s : *part) updater.addSiblings(s.first, s.values);
  }
  return cells;
}

template <typename Gone>
void FusionCache::dropIf(Gone gone) {
  for (auto it = blocks_.begin(); it != blocks_.end();) {
    if (gone(*it->second))
      it = blocks_.erase(it);
    else
      ++it;
  }
}

size_t FusionCache::writeBack(AccumulatingOcTree* tree, WorkerPool* pool,
                              AccumulatingOcTree::WorkerCounters* counters) {
  const size_t cells = writeBackIf(tree, pool, counters, [](const Block&) { return true; });
  dropIf([this](const Block& b) { return b.last_update + kIdleUpdates <= updates_; });
  return cells;
}

namespace {
/// The block @p b overlaps the keys [lo, hi].
bool overlaps(const FusionCache::Block& b, const octomap::OcTreeKey& lo, const octomap::OcTreeKey& hi) {
  for (int a = 0; a < 3; ++a)
    if (b.first[a] + FusionCache::kEdge - 1 < lo[a] || b.first[a] > hi[a]) return false;
  return true;
}
}  // namespace

size_t FusionCache::writeBack(AccumulatingOcTree* tree, const octomap::OcTreeKey& lo, const octomap::OcTreeKey& hi,
                              WorkerPool* pool, AccumulatingOcTree::WorkerCounters* counters) {
  return writeBackIf(tree, pool, counters, [&](const Block& b) { return overlaps(b, lo, hi); });
}

size_t FusionCache::maintain(AccumulatingOcTree* tree, WorkerPool* pool, AccumulatingOcTree::WorkerCounters* counters) {
  const size_t cells = writeBackIf(tree, pool, counters, [this](const Block& b) {
    return b.write_due <= updates_ || b.last_update + kIdleUpdates <= updates_;
  });
  dropIf([this](const Block& b) { return !b.unwritten && b.last_update + kIdleUpdates <= updates_; });
  return cells;
}

void FusionCache::drop(const octomap::OcTreeKey& lo, const octomap::OcTreeKey& hi) {
  dropIf([&](const Block& b) { return overlaps(b, lo, hi); });
}

void FusionCache::clear() { blocks_.clear(); }

std::vector<octomap::OcTreeKey> FusionCache::unwrittenBlocks(const octomap::OcTreeKey& lo,
                                                             const octomap::OcTreeKey& hi) const {
  std::vector<octomap::OcTreeKey> keys;
  for (const auto& entry : blocks_)
    if (entry.second->unwritten && overlaps(*entry.second, lo, hi)) keys.push_back(entry.second->first);
  return keys;
}

size_t FusionCache::unwrittenBlocks() const {
  size_t n = 0;
  for (const auto& entry : blocks_) n += entry.second->unwritten;
  return n;
}

}  // namespace stereo_occupancy
