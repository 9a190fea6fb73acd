#include "stereo_occupancy/distance_field.h"

#include <algorithm>
#include <cstdlib>  // aligned_alloc, free
#include <cstring>
#include <limits>
#include <stdexcept>
#include <type_traits>

#ifdef __SSE2__
#include <emmintrin.h>
#endif
#ifdef __linux__
#include <sys/mman.h>  // madvise
#endif

#include "stereo_occupancy/accumulating_octree.h"  // leafOverlaps

namespace stereo_occupancy {

namespace {

/// The window re-centres when the vehicle is farther than this from its centre along an axis [blocks].
constexpr double kRecentreBlocks = 1.0;
/// Global cell index of OctoMap key 0 (the key of index 0 is 32768).
constexpr int kKeyOffset = 32768;

int floorDiv(int g, int n) { return g >= 0 ? g / n : -((-g + n - 1) / n); }
int positiveMod(int g, int n) { return g - floorDiv(g, n) * n; }

/// Puts block @p linear in @p list once per epoch.
void mark(int linear, uint32_t epoch, std::vector<uint32_t>* marks, std::vector<int>* list) {
  if ((*marks)[static_cast<size_t>(linear)] == epoch) return;
  (*marks)[static_cast<size_t>(linear)] = epoch;
  list->push_back(linear);
}

/// sample()'s answer outside the window (or at a NaN point).
DistanceSample outsideSample() {
  DistanceSample s;
  s.distance_m = std::numeric_limits<float>::quiet_NaN();
  return s;
}

/// Asks the cache for the line at @p address ahead of its read (a hint: no
/// fault, no effect on the answers); nothing where the compiler has no such builtin.
inline void prefetchRead(const void* address) {
#if defined(__GNUC__)
  __builtin_prefetch(address, /*rw=*/0, /*locality=*/3);
#else
  (void)address;
#endif
}

}  // namespace

namespace detail {

void* allocateHugePages(size_t bytes) {
#ifdef __linux__
  if (bytes >= kHugePageBytes) {
    if (bytes > std::numeric_limits<size_t>::max() - kHugePageBytes) throw std::bad_alloc();
    // Whole huge pages, aligned to them: a transparent huge page backs an aligned 2 MiB only.
    const size_t rounded = (bytes + kHugePageBytes - 1) / kHugePageBytes * kHugePageBytes;
    void* p = std::aligned_alloc(kHugePageBytes, rounded);
    if (p == nullptr) throw std::bad_alloc();
#ifdef MADV_HUGEPAGE
    // Before the first touch, so that the faults take huge pages. Refused
    // (no THP, an old kernel): small pages, the same answers.
    (void)madvise(p, rounded, MADV_HUGEPAGE);
#endif
    return p;
  }
#endif
  return ::operator new(bytes);
}

void freeHugePages(void* p, size_t bytes) {
#ifdef __linux__
  if (bytes >= kHugePageBytes) {
    std::free(p);
    return;
  }
#endif
  ::operator delete(p);
}

}  // namespace detail

DistanceField::DistanceField(const DistanceFieldConfig& config, double resolution_m)
    : config_(config), resolution_m_(resolution_m) {
  std::string why;
  if (!config_.isValid(&why)) throw std::invalid_argument("distance field: " + why);
  if (!(resolution_m > 0.0) || !std::isfinite(resolution_m))
    throw std::invalid_argument("distance field: the resolution must be positive, not " + std::to_string(resolution_m));
  const double edges_m[3] = {config_.window_xy_m, config_.window_xy_m, config_.window_z_m};
  double cells = 1.0;
  for (int a = 0; a < 3; ++a) {
    const double blocks = std::max(1.0, std::ceil(edges_m[a] / resolution_m / kBlockCells - 1e-9));
    cells *= blocks * kBlockCells;
    size_blocks_[a] = static_cast<int>(std::min(blocks, 1e6));
  }
  if (cells > static_cast<double>(kMaxWindowCells))
    throw std::invalid_argument("distance field: a window of " + std::to_string(config_.window_xy_m) + " x " +
                                std::to_string(config_.window_xy_m) + " x " + std::to_string(config_.window_z_m) +
                                " m at " + std::to_string(resolution_m) + " m holds more than " +
                                std::to_string(kMaxWindowCells) + " cells");
  size_cells_ = size_blocks_ * kBlockCells;
  // Distances saturate from sqrt(saturated_sq_) cells on: the smallest
  // integer c with sqrt(c) * resolution >= max_distance_m. Every squared
  // distance below it has each axis offset at most reach_cells_.
  const double reach = config_.max_distance_m / resolution_m;
  const double saturated_sq = std::max(1.0, std::ceil(reach * reach * (1.0 - 1e-12)));
  // Unreachable within kMaxWindowCells and the ranges of max_distance_m; cells_ holds it in kClassShift bits.
  if (saturated_sq > static_cast<double>(kSqMask))
    throw std::invalid_argument("distance field: max_distance_m is too many cells of " + std::to_string(resolution_m) +
                                " m");
  saturated_sq_ = static_cast<uint32_t>(saturated_sq);
  reach_cells_ = static_cast<int>(std::floor(std::sqrt(static_cast<double>(saturated_sq_ - 1))));
  while (static_cast<uint32_t>(reach_cells_ * reach_cells_) > saturated_sq_ - 1) --reach_cells_;
  while (static_cast<uint32_t>((reach_cells_ + 1) * (reach_cells_ + 1)) <= saturated_sq_ - 1) ++reach_cells_;
  reach_blocks_ = (reach_cells_ + kBlockCells - 1) / kBlockCells;

  const size_t n = static_cast<size_t>(size_cells_.x()) * size_cells_.y() * size_cells_.z();
  const size_t blocks = n / kBlockVolume;
  classes_.assign(n, static_cast<uint8_t>(CellClass::kUnknown));
  // Everything unknown: an obstacle everywhere, or none.
  static_assert(static_cast<uint32_t>(CellClass::kUnknown) == 0, "cells_ starts unknown");
  cells_.assign(n, config_.unknown_is_occupied ? 0u : saturated_sq_);
  narrow_ = saturated_sq_ <= kMaxNarrowSq;
  if (narrow_)
    allocatePasses(n, &narrow_values_);
  else
    allocatePasses(n, &wide_values_);
  row_span_.assign(static_cast<size_t>(kBlockCells + 2 * reach_blocks_ * kBlockCells), 0);
  span_blocks_.assign(static_cast<size_t>(2 * reach_blocks_ + 1), nullptr);
  rows_x_.assign(blocks, 0);
  rows_xy_.assign(blocks, 0);
  for (auto* marks : {&changed_mark_, &mark_x_, &mark_y_, &mark_z_}) marks->assign(blocks, 0);
  for (auto* list : {&changed_, &blocks_x_, &blocks_y_, &blocks_z_}) list->reserve(blocks);
  origin_block_ = -size_blocks_ / 2;
  for (int a = 0; a < 3; ++a) ring_phase_[a] = positiveMod(origin_block_[a], size_blocks_[a]);
}

Eigen::AlignedBox3d DistanceField::window() const {
  const Eigen::Vector3d lo = (origin_block_ * kBlockCells).cast<double>() * resolution_m_;
  return Eigen::AlignedBox3d(lo, lo + size_cells_.cast<double>() * resolution_m_);
}

bool DistanceField::localCell(const Eigen::Vector3d& W_point, Eigen::Vector3i* l) const {
  // In cells from the window's lowest corner; compared as doubles first: the
  // index of a far point (or NaN) would not fit an int.
  const Eigen::Array3d c =
      (W_point.array() / resolution_m_).floor() - (origin_block_ * kBlockCells).cast<double>().array();
  if (!((c >= 0.0).all() && (c < size_cells_.cast<double>().array()).all())) return false;
  *l = c.cast<int>().matrix();
  return true;
}

Eigen::Vector3d DistanceField::centreOf(const Eigen::Vector3i& l) const {
  return ((l + origin_block_ * kBlockCells).cast<double>() + Eigen::Vector3d::Constant(0.5)) * resolution_m_;
}

Eigen::Vector3i DistanceField::blockOfLinear(int linear) const {
  const int x = linear % size_blocks_.x();
  const int yz = linear / size_blocks_.x();
  return Eigen::Vector3i(x, yz % size_blocks_.y(), yz / size_blocks_.y());
}

// --- update -------------------------------------------------------------------

void DistanceField::update(const octomap::OcTree& map, const std::vector<CellClassChange>& changes,
                           const std::vector<CellBox>& regions, bool all, const Eigen::Vector3d& W_vehicle) {
  checkResolution(map);
  update([&map](const CellBox&) -> const octomap::OcTree& { return map; }, changes, regions, all, W_vehicle);
}

void DistanceField::checkResolution(const octomap::OcTree& map) const {
  if (std::abs(map.getResolution() - resolution_m_) > 1e-9 * resolution_m_)
    throw std::invalid_argument("distance field: the map's resolution " + std::to_string(map.getResolution()) +
                                " m is not the field's " + std::to_string(resolution_m_) + " m");
}

void DistanceField::update(const MapSource& source, const std::vector<CellClassChange>& changes,
                           const std::vector<CellBox>& regions, bool all, const Eigen::Vector3d& W_vehicle) {
  bool checked = false;
  const MapSource map = [&](const CellBox& cells) -> const octomap::OcTree& {
    const octomap::OcTree& tree = source(cells);
    if (!checked) {
      checkResolution(tree);
      occupied_log_odds_ = tree.getOccupancyThresLog();
      checked = true;
    }
    return tree;
  };
  const Eigen::Vector3i origin = W_vehicle.allFinite() ? wantedOrigin(W_vehicle) : origin_block_;
  const bool read_all = !placed_ || all || ((origin - origin_block_).array().abs() >= size_blocks_.array()).any();
  const CellBox window_cells = windowCellsAt(origin);
  const bool reads = read_all || origin != origin_block_ ||
                     std::any_of(regions.begin(), regions.end(),
                                 [&](const CellBox& region) { return !region.intersection(window_cells).isEmpty(); });
  if (reads) map(CellBox());  // the map's resolution checked before anything changes
  ++epoch_;
  everything_ = false;
  last_read_cells_ = 0;
  for (auto* list : {&changed_, &blocks_x_, &blocks_y_, &blocks_z_}) list->clear();
  if (read_all) {
    // First, a jump beyond the window, or a map changed everywhere: read it all.
    origin_block_ = origin;
    for (int a = 0; a < 3; ++a) ring_phase_[a] = positiveMod(origin_block_[a], size_blocks_[a]);
    readAll(map);
    placed_ = true;
  } else {
    if (origin != origin_block_) moveTo(map, origin);
    applyChanges(changes);
    // After the changes: the map's cells in the regions are the newer word.
    for (const CellBox& region : regions)
      if (!region.intersection(windowCells()).isEmpty()) readRegion(map, region);
  }
  recompute();
}

Eigen::Vector3i DistanceField::wantedOrigin(const Eigen::Vector3d& W_vehicle) const {
  const double block_m = kBlockCells * resolution_m_;
  // Within the OcTree's key range: an index beyond it would not fit an int.
  const double limit_m = (kKeyOffset + 1.0) * resolution_m_;
  const Eigen::Vector3d W_v = W_vehicle.cwiseMax(-limit_m).cwiseMin(limit_m);
  const Eigen::Vector3d W_centre = window().center();
  Eigen::Vector3i origin = origin_block_;
  for (int a = 0; a < 3; ++a) {
    // Hysteresis: the window follows once the vehicle is a block off its
    // centre, so a vehicle hovering on a block's face does not move it to and fro.
    if (placed_ && std::abs(W_v[a] - W_centre[a]) <= kRecentreBlocks * block_m) continue;
    origin[a] = static_cast<int>(std::floor(W_v[a] / block_m)) - size_blocks_[a] / 2;
  }
  return origin;
}

void DistanceField::moveTo(const MapSource& map, const Eigen::Vector3i& origin_block) {
  const Eigen::Vector3i old_origin = origin_block_;
  const Eigen::Vector3i shift = origin_block - old_origin;
  // The cells within reach of the side that leaves: their nearest obstacle
  // may leave with it (or, unknown being occupied, the outside comes
  // nearer), unless the blocks that leave were what the outside counts as.
  // Decided per column of blocks that leave, before the entering blocks reuse their slots.
  for (int a = 0; a < 3; ++a) {
    if (shift[a] == 0) continue;
    const int u = (a + 1) % 3, v = (a + 2) % 3, r = reach_blocks_, n = size_blocks_[a];
    const int band_lo = shift[a] > 0 ? 0 : std::max(0, n - r), band_hi = shift[a] > 0 ? std::min(r, n) : n;
    // The global layers that leave within reach of the new edge.
    const int leave_lo = shift[a] > 0 ? origin_block[a] - r : origin_block[a] + n;
    // Columns beyond the new window's sides too: a block that leaves there
    // (a move along two axes) may still be within reach of the band.
    Eigen::Vector3i column;
    for (column[v] = -r; column[v] < size_blocks_[v] + r; ++column[v])
      for (column[u] = -r; column[u] < size_blocks_[u] + r; ++column[u]) {
        bool differs = false;
        for (int k = 0; k < r && !differs; ++k) {
          Eigen::Vector3i g = origin_block + column;
          g[a] = leave_lo + k;
          const Eigen::Vector3i old_local = g - old_origin;
          if ((old_local.array() < 0).any() || (old_local.array() >= size_blocks_.array()).any()) continue;
          differs = differsFromOutside(globalSlot(g));
        }
        if (!differs) continue;
        // Its obstacles reach the band's blocks of the columns within reach.
        Eigen::Vector3i b;
        for (b[v] = std::max(0, column[v] - r); b[v] <= std::min(size_blocks_[v] - 1, column[v] + r); ++b[v])
          for (b[u] = std::max(0, column[u] - r); b[u] <= std::min(size_blocks_[u] - 1, column[u] + r); ++b[u])
            for (b[a] = band_lo; b[a] < band_hi; ++b[a]) mark(linearOfBlock(b), epoch_, &mark_z_, &blocks_z_);
      }
  }
  origin_block_ = origin_block;
  for (int a = 0; a < 3; ++a) ring_phase_[a] = positiveMod(origin_block_[a], size_blocks_[a]);
  // The blocks that enter: a slab per axis that moved, each without the
  // slabs of the axes before it (local block ranges [lo, hi)).
  Eigen::Vector3i rest_lo = Eigen::Vector3i::Zero(), rest_hi = size_blocks_;
  for (int a = 0; a < 3; ++a) {
    if (shift[a] == 0) continue;
    Eigen::Vector3i lo = rest_lo, hi = rest_hi;
    if (shift[a] > 0) {
      lo[a] = size_blocks_[a] - shift[a];
      rest_hi[a] = lo[a];
    } else {
      hi[a] = -shift[a];
      rest_lo[a] = hi[a];
    }
    readBlocks(map, lo, hi);
  }
}

size_t DistanceField::globalSlot(const Eigen::Vector3i& global_block) const {
  return static_cast<size_t>(positiveMod(global_block.x(), size_blocks_.x())) +
         static_cast<size_t>(size_blocks_.x()) * (positiveMod(global_block.y(), size_blocks_.y()) +
                                                  size_blocks_.y() * positiveMod(global_block.z(), size_blocks_.z()));
}

bool DistanceField::differsFromOutside(size_t slot) const {
  // Eight classes at a time: kOccupied (2) has bit 1, kFree (1) bit 0.
  const uint8_t* c = &classes_[slot * kBlockVolume];
  constexpr uint64_t kLowBits = 0x0101010101010101ull;
  for (int i = 0; i < kBlockVolume; i += 8) {
    uint64_t w;
    std::memcpy(&w, c + i, sizeof w);
    // Outside is an obstacle (unknown occupied): a free cell differs; else an occupied one.
    if (config_.unknown_is_occupied ? (w & kLowBits) : ((w >> 1) & kLowBits)) return true;
  }
  return false;
}

void DistanceField::readAll(const MapSource& map) {
  everything_ = true;
  readClasses(map, Eigen::Vector3i::Zero(), size_blocks_);
}

void DistanceField::readBlocks(const MapSource& map, const Eigen::Vector3i& lo, const Eigen::Vector3i& hi) {
  if ((hi.array() <= lo.array()).any()) return;
  readClasses(map, lo, hi);
  markEntered(lo, hi);
}

CellBox DistanceField::windowCellsAt(const Eigen::Vector3i& origin_block) const {
  const Eigen::Vector3i origin_cell = origin_block * kBlockCells;
  return CellBox(origin_cell, origin_cell + size_cells_ - Eigen::Vector3i::Ones());
}

void DistanceField::readRegion(const MapSource& map, const CellBox& cells) {
  const Eigen::Vector3i origin_cell = origin_block_ * kBlockCells;
  const CellBox in_window = cells.intersection(windowCells());
  if (in_window.isEmpty()) return;
  const Eigen::Vector3i lo = (in_window.min() - origin_cell) / kBlockCells;
  const Eigen::Vector3i hi = (in_window.max() - origin_cell) / kBlockCells + Eigen::Vector3i::Ones();
  // A block whose obstacles went or came changes its neighbours' distances.
  region_differed_.clear();
  for (int z = lo.z(); z < hi.z(); ++z)
    for (int y = lo.y(); y < hi.y(); ++y)
      for (int x = lo.x(); x < hi.x(); ++x)
        region_differed_.push_back(differsFromOutside(slotOf(Eigen::Vector3i(x, y, z))));
  readClasses(map, lo, hi);
  if (everything_) return;
  size_t i = 0;
  for (int z = lo.z(); z < hi.z(); ++z)
    for (int y = lo.y(); y < hi.y(); ++y)
      for (int x = lo.x(); x < hi.x(); ++x) {
        const Eigen::Vector3i b(x, y, z);
        if (region_differed_[i++] || differsFromOutside(slotOf(b)))
          markChanged(b);
        else
          mark(linearOfBlock(b), epoch_, &mark_z_, &blocks_z_);
      }
}

void DistanceField::readClasses(const MapSource& source, const Eigen::Vector3i& lo, const Eigen::Vector3i& hi) {
  if ((hi.array() <= lo.array()).any()) return;
  last_read_cells_ += static_cast<size_t>((hi - lo).prod()) * kBlockVolume;
  for (int z = lo.z(); z < hi.z(); ++z)
    for (int y = lo.y(); y < hi.y(); ++y)
      for (int x = lo.x(); x < hi.x(); ++x) {
        const Eigen::Vector3i b(x, y, z);
        std::memset(&classes_[slotOf(b) * kBlockVolume], static_cast<int>(CellClass::kUnknown), kBlockVolume);
      }
  const CellBox cells((origin_block_ + lo) * kBlockCells, (origin_block_ + hi) * kBlockCells - Eigen::Vector3i::Ones());
  octomap::OcTreeKey key_lo, key_hi;
  if (!keysOfCells(cells, kKeyOffset, &key_lo, &key_hi)) return;  // beyond the key range the map holds nothing
  const octomap::OcTree& map = source(cells);
  const unsigned depth = map.getTreeDepth();
  for (auto it = map.begin_leafs_bbx(key_lo, key_hi), end = map.end_leafs_bbx(); it != end; ++it) {
    if (!leafOverlaps(it, depth, key_lo, key_hi)) continue;  // octomap 1.9 hands out some just outside
    const uint8_t cell_class = static_cast<uint8_t>(classOfLogOdds(it->getLogOdds(), occupied_log_odds_));
    // A pruned leaf covers several cells: its part inside the box.
    const octomap::OcTreeKey first = it.getIndexKey();
    const int side = 1 << (depth - it.getDepth());
    Eigen::Vector3i from, to;
    for (int a = 0; a < 3; ++a) {
      from[a] = std::max<int>(first[a], key_lo[a]) - kKeyOffset - origin_block_[a] * kBlockCells;
      to[a] = std::min<int>(first[a] + side - 1, key_hi[a]) - kKeyOffset - origin_block_[a] * kBlockCells;
    }
    Eigen::Vector3i l;
    for (l.z() = from.z(); l.z() <= to.z(); ++l.z())
      for (l.y() = from.y(); l.y() <= to.y(); ++l.y())
        for (l.x() = from.x(); l.x() <= to.x(); ++l.x()) classes_[cellIndex(l)] = cell_class;
  }
}

void DistanceField::markEntered(const Eigen::Vector3i& lo, const Eigen::Vector3i& hi) {
  if (everything_) return;
  // A block that entered is computed; only one that holds what the outside
  // did not (an obstacle, or with unknown occupied a free cell) can change
  // its neighbours' distances.
  for (int z = lo.z(); z < hi.z(); ++z)
    for (int y = lo.y(); y < hi.y(); ++y)
      for (int x = lo.x(); x < hi.x(); ++x) {
        const Eigen::Vector3i b(x, y, z);
        if (differsFromOutside(slotOf(b)))
          markChanged(b);
        else
          mark(linearOfBlock(b), epoch_, &mark_z_, &blocks_z_);
      }
}

void DistanceField::applyChanges(const std::vector<CellClassChange>& changes) {
  const Eigen::Vector3i origin_cell = origin_block_ * kBlockCells;
  for (const CellClassChange& c : changes) {
    const Eigen::Vector3i l = c.cell - origin_cell;
    if (!inside(l)) continue;  // read from the map when it enters
    const size_t index = cellIndex(l);
    uint8_t& cell_class = classes_[index];
    const uint8_t now = static_cast<uint8_t>(c.now);
    if (cell_class == now) continue;
    cells_[index] = sqOf(cells_[index]) | (uint32_t{now} << kClassShift);  // the distance follows if it moves
    // Only a change of obstacle status moves distances (unknown -> free, the
    // most common, does not unless unknown is occupied).
    const bool moved = isObstacle(cell_class) != isObstacle(now);
    cell_class = now;
    if (moved) markChanged(Eigen::Vector3i(l.x() >> kBlockShift, l.y() >> kBlockShift, l.z() >> kBlockShift));
  }
}

void DistanceField::markChanged(const Eigen::Vector3i& local_block) {
  mark(linearOfBlock(local_block), epoch_, &changed_mark_, &changed_);
}

void DistanceField::markRecompute(const Eigen::Vector3i& lo, const Eigen::Vector3i& hi) {
  for (int z = lo.z(); z < hi.z(); ++z)
    for (int y = lo.y(); y < hi.y(); ++y)
      for (int x = lo.x(); x < hi.x(); ++x) {
        const Eigen::Vector3i b(x, y, z);
        mark(linearOfBlock(b), epoch_, &mark_z_, &blocks_z_);
      }
}

void DistanceField::recompute() {
  if (everything_) {
    for (int i = 0, n = static_cast<int>(changed_mark_.size()); i < n; ++i) {
      blocks_x_.push_back(i);
      blocks_y_.push_back(i);
      blocks_z_.push_back(i);
    }
  } else {
    // Only cells within reach of a changed cell can change: the changed
    // blocks dilated by the reach (pass 3, along z), then the cells pass 3
    // reads (dilated along z: pass 2), then the cells pass 2 reads (along y: pass 1).
    const int r = reach_blocks_;
    auto dilate = [&](const std::vector<int>& from, const Eigen::Vector3i& by, std::vector<uint32_t>* marks,
                      std::vector<int>* list) {
      for (size_t i = 0; i < from.size(); ++i) {
        const Eigen::Vector3i b = blockOfLinear(from[i]);
        const Eigen::Vector3i lo = (b - by).cwiseMax(0), hi = (b + by).cwiseMin(size_blocks_ - Eigen::Vector3i::Ones());
        for (int z = lo.z(); z <= hi.z(); ++z)
          for (int y = lo.y(); y <= hi.y(); ++y)
            for (int x = lo.x(); x <= hi.x(); ++x) {
              const Eigen::Vector3i d(x, y, z);
              mark(linearOfBlock(d), epoch_, marks, list);
            }
      }
    };
    dilate(changed_, Eigen::Vector3i::Constant(r), &mark_z_, &blocks_z_);
    dilate(blocks_z_, Eigen::Vector3i(0, 0, r), &mark_y_, &blocks_y_);
    dilate(blocks_y_, Eigen::Vector3i(0, r, 0), &mark_x_, &blocks_x_);
  }
  if (narrow_)
    runPasses(&narrow_values_);
  else
    runPasses(&wide_values_);
  last_updated_cells_ = blocks_z_.size() * kBlockVolume;
}

namespace {
/// The obstacle flags of the 8 cells (CellClass bytes) at @p classes as
/// bits 0..7. kOccupied (2) has bit 1 set; with unknown occupied, every
/// class but kFree (1) is an obstacle: bit 0 clear.
inline uint64_t obstacleBits(const uint8_t* classes, bool unknown_is_occupied) {
  static_assert(static_cast<int>(CellClass::kOccupied) == 2 && static_cast<int>(CellClass::kFree) == 1 &&
                    static_cast<int>(CellClass::kUnknown) == 0,
                "the bit tests below");
  uint64_t v;
  std::memcpy(&v, classes, sizeof v);
  constexpr uint64_t kLowBits = 0x0101010101010101ull;
  const uint64_t flags = unknown_is_occupied ? (~v & kLowBits) : ((v >> 1) & kLowBits);
  return (flags * 0x0102040810204080ull) >> 56;  // byte i's low bit to bit i
}
}  // namespace

template <typename T>
void DistanceField::allocatePasses(size_t cells, PassValues<T>* values) {
  const T cap = static_cast<T>(saturated_sq_);
  values->x.assign(cells, cap);
  values->xy.assign(cells, cap);
  const int d = reach_cells_;
  values->add_rows.clear();
  for (int k = -d; k <= d; ++k) values->add_rows.insert(values->add_rows.end(), kBlockCells, static_cast<T>(k * k));
  values->span.assign(static_cast<size_t>(2 * reach_blocks_ + 1), nullptr);
  values->span_rows.assign(static_cast<size_t>(2 * reach_blocks_ + 1), 0);
  values->rows.assign(static_cast<size_t>(2 * reach_blocks_ * kBlockCells + kBlockCells), nullptr);
}

template <typename T>
void DistanceField::runPasses(PassValues<T>* values) {
  for (int b : blocks_x_) alongX(blockOfLinear(b), &values->x);
  for (int b : blocks_y_) alongY(blockOfLinear(b), values);
  for (int b : blocks_z_) alongZ(blockOfLinear(b), values);
}

// Pass 1: per row of a block, the distance along x to the nearest obstacle
// within reach (squared), from the row's obstacle bits and the reach's on
// both sides: the nearest set bit on each side of each cell.
template <typename T>
void DistanceField::alongX(const Eigen::Vector3i& b, std::vector<T>* values) {
  const int r = reach_blocks_, d = reach_cells_;
  if (r > kMaxBitReachBlocks) return alongXScalar(b, values);
  const bool uio = config_.unknown_is_occupied;
  const T cap = static_cast<T>(saturated_sq_);
  T* out = &(*values)[slotOf(b) * kBlockVolume];
  // The rows' obstacle bits of the span's blocks, left to right (all or
  // none outside the window).
  uint64_t words[kBlockCells * kBlockCells] = {};
  for (int i = 0; i <= 2 * r; ++i) {
    const Eigen::Vector3i n(b.x() - r + i, b.y(), b.z());
    const int shift = i * kBlockCells;
    if (n.x() < 0 || n.x() >= size_blocks_.x()) {
      if (uio)
        for (uint64_t& w : words) w |= uint64_t{0xff} << shift;
      continue;
    }
    const uint8_t* c = &classes_[slotOf(n) * kBlockVolume];
    for (int row = 0; row < kBlockCells * kBlockCells; ++row)
      words[row] |= obstacleBits(c + row * kBlockCells, uio) << shift;
  }
  const int first = r * kBlockCells;  // the block's first cell in a word
  uint64_t finite_rows = 0;           // the rows with an obstacle within reach along x
  for (int row = 0; row < kBlockCells * kBlockCells; ++row) {
    const uint64_t w = words[row];
    T* o = out + row * kBlockCells;
    if (w == 0) {
      std::fill(o, o + kBlockCells, cap);
      continue;
    }
    bool any = false;
    for (int x = 0; x < kBlockCells; ++x) {
      const int p = first + x;
      int dist = d + 1;
      const uint64_t left = w & ((uint64_t{2} << p) - 1);  // positions <= p
      if (left) dist = p - (63 - __builtin_clzll(left));
      const uint64_t right = w >> p;
      if (right) dist = std::min(dist, __builtin_ctzll(right));
      o[x] = dist <= d ? static_cast<T>(dist * dist) : cap;
      any = any || dist <= d;
    }
    finite_rows |= uint64_t{any} << row;
  }
  rows_x_[slotOf(b)] = finite_rows;
}

// Pass 1 for reaches beyond kMaxBitReachBlocks: a scan of the row's flags.
template <typename T>
void DistanceField::alongXScalar(const Eigen::Vector3i& b, std::vector<T>* values) {
  const int r = reach_blocks_, d = reach_cells_;
  const uint8_t outside = config_.unknown_is_occupied ? 1 : 0;
  const T cap = static_cast<T>(saturated_sq_);
  T* out = &(*values)[slotOf(b) * kBlockVolume];
  const uint8_t** rows = span_blocks_.data();  // the class blocks of the span, null outside the window
  const int span_blocks = 2 * r + 1;
  for (int i = 0; i < span_blocks; ++i) {
    const Eigen::Vector3i n(b.x() - r + i, b.y(), b.z());
    rows[i] = (n.x() >= 0 && n.x() < size_blocks_.x()) ? &classes_[slotOf(n) * kBlockVolume] : nullptr;
  }
  uint8_t* span = row_span_.data();   // obstacle flags of positions [-r * 8, (r + 1) * 8) around the block
  const int first = r * kBlockCells;  // the block's first cell in span
  uint64_t finite_rows = 0;           // the rows with an obstacle within reach along x
  for (int row = 0; row < kBlockCells * kBlockCells; ++row) {
    for (int i = 0; i < span_blocks; ++i) {
      uint8_t* s = span + i * kBlockCells;
      if (!rows[i]) {
        std::memset(s, outside, kBlockCells);
        continue;
      }
      const uint8_t* c = rows[i] + row * kBlockCells;
      for (int x = 0; x < kBlockCells; ++x) s[x] = isObstacle(c[x]) ? 1 : 0;
    }
    int dist[kBlockCells];
    int last = std::numeric_limits<int>::min() / 2;  // the nearest obstacle on the left
    for (int p = first - d; p < first + kBlockCells; ++p) {
      if (span[p]) last = p;
      if (p >= first) dist[p - first] = p - last;
    }
    int next = std::numeric_limits<int>::max() / 2;  // on the right
    for (int p = first + kBlockCells - 1 + d; p >= first; --p) {
      if (span[p]) next = p;
      if (p < first + kBlockCells) dist[p - first] = std::min(dist[p - first], next - p);
    }
    T* o = out + row * kBlockCells;
    bool any = false;
    for (int x = 0; x < kBlockCells; ++x) {
      o[x] = dist[x] <= d ? static_cast<T>(dist[x] * dist[x]) : cap;
      any = any || dist[x] <= d;
    }
    finite_rows |= uint64_t{any} << row;
  }
  rows_x_[slotOf(b)] = finite_rows;
}

namespace {
/// The core of passes 2 and 3, on the 8 lanes x of a row:
/// out[x] = min(cap, min over i < n of rows[i][offset + x] + add[8 i + x]);
/// true if any out[x] is below cap. Every value is at most cap and every
/// add below it, so the sums fit the lanes as signed numbers (SSE2 compares
/// signed lanes only). The scalar version, for any width (32-bit lanes, and
/// 16-bit ones without SSE2: compilers vectorise it, e.g. with NEON).
template <typename T>
inline bool minPlusRowsScalar(const T* const* rows, size_t offset, const T* add, int n, T cap, T* out) {
  using Signed = std::make_signed_t<T>;
  Signed acc[DistanceField::kBlockCells];
  std::fill(acc, acc + DistanceField::kBlockCells, static_cast<Signed>(cap));
  for (int i = 0; i < n; ++i) {
    const T* row = rows[i] + offset;
    const T* k = add + i * DistanceField::kBlockCells;
    for (int x = 0; x < DistanceField::kBlockCells; ++x) acc[x] = std::min(acc[x], static_cast<Signed>(row[x] + k[x]));
  }
  bool any = false;
  for (int x = 0; x < DistanceField::kBlockCells; ++x) {
    out[x] = static_cast<T>(acc[x]);
    any = any || out[x] < cap;
  }
  return any;
}

inline bool minPlusRows(const uint32_t* const* rows, size_t offset, const uint32_t* add, int n, uint32_t cap,
                        uint32_t* out) {
  return minPlusRowsScalar(rows, offset, add, n, cap, out);
}

inline bool minPlusRows(const uint16_t* const* rows, size_t offset, const uint16_t* add, int n, uint16_t cap,
                        uint16_t* out) {
#ifdef __SSE2__
  static_assert(DistanceField::kBlockCells * sizeof(uint16_t) == sizeof(__m128i), "a row is one register");
  const __m128i c = _mm_set1_epi16(static_cast<int16_t>(cap));
  __m128i acc = c;
  for (int i = 0; i < n; ++i) {
    const __m128i v = _mm_loadu_si128(reinterpret_cast<const __m128i*>(rows[i] + offset));
    const __m128i k = _mm_loadu_si128(reinterpret_cast<const __m128i*>(add + i * DistanceField::kBlockCells));
    acc = _mm_min_epi16(acc, _mm_add_epi16(v, k));
  }
  _mm_storeu_si128(reinterpret_cast<__m128i*>(out), acc);
  return _mm_movemask_epi8(_mm_cmplt_epi16(acc, c)) != 0;
#else
  return minPlusRowsScalar(rows, offset, add, n, cap, out);
#endif
}
}  // namespace

template <typename T>
bool DistanceField::gatherSpan(const Eigen::Vector3i& b, int axis, const std::vector<T>& values,
                               const std::vector<uint64_t>& rows, std::vector<const T*>* span,
                               uint64_t* span_rows) const {
  const int r = reach_blocks_;
  // Unknown outside is an obstacle: the outside's rows hold 0.
  bool any = config_.unknown_is_occupied && (b[axis] - r < 0 || b[axis] + r >= size_blocks_[axis]);
  for (int i = 0; i <= 2 * r; ++i) {
    Eigen::Vector3i n = b;
    n[axis] += i - r;
    if (n[axis] < 0 || n[axis] >= size_blocks_[axis]) {
      (*span)[static_cast<size_t>(i)] = nullptr;
      span_rows[i] = 0;
      continue;
    }
    const size_t slot = slotOf(n);
    (*span)[static_cast<size_t>(i)] = &values[slot * kBlockVolume];
    span_rows[i] = rows[slot];
    any = any || rows[slot] != 0;
  }
  return any;
}

namespace {
/// The 8 x 8 bit matrix @p x (bit 8 i + j) transposed (bit 8 j + i).
inline uint64_t transpose8(uint64_t x) {
  uint64_t t = (x ^ (x >> 7)) & 0x00AA00AA00AA00AAull;
  x = x ^ t ^ (t << 7);
  t = (x ^ (x >> 14)) & 0x0000CCCC0000CCCCull;
  x = x ^ t ^ (t << 14);
  t = (x ^ (x >> 28)) & 0x00000000F0F0F0F0ull;
  return x ^ t ^ (t << 28);
}
}  // namespace

// Pass 2: g(x, y) = min over |k| <= reach of pass 1's g(x, y + k) + k^2,
// each row of 8 cells at once.
template <typename T>
void DistanceField::alongY(const Eigen::Vector3i& b, PassValues<T>* values) {
  const int d = reach_cells_, first = reach_blocks_ * kBlockCells;
  const T cap = static_cast<T>(saturated_sq_);
  const size_t slot = slotOf(b);
  T* out = &values->xy[slot * kBlockVolume];
  uint64_t* span_rows = values->span_rows.data();
  if (!gatherSpan(b, 1, values->x, rows_x_, &values->span, span_rows)) {  // no obstacle within reach: nothing to do
    std::fill(out, out + kBlockVolume, cap);
    rows_xy_[slot] = 0;
    return;
  }
  const bool uio = config_.unknown_is_occupied;
  T outside_row[kBlockCells];
  std::fill(outside_row, outside_row + kBlockCells, uio ? T{0} : cap);
  // The span's rows of a layer fit one word up to kMaxBitReachBlocks: then
  // rows with nothing within reach of a row are skipped.
  const bool by_row = reach_blocks_ <= kMaxBitReachBlocks;
  const uint64_t reach_bits = by_row ? (uint64_t{2} << (2 * d)) - 1 : 0;  // 2d + 1 rows, fewer than 64 by_row
  const T** rows = values->rows.data();  // the span's rows at this z, by their y in the span
  uint64_t finite_rows = 0;
  for (int z = 0; z < kBlockCells; ++z) {
    T* layer = out + (z << (2 * kBlockShift));
    uint64_t live = ~uint64_t{0};  // bit yy: the span's row yy may hold a value below cap
    if (by_row) {
      live = 0;
      for (int i = 0; i <= 2 * reach_blocks_; ++i) {
        const uint64_t bits =
            values->span[static_cast<size_t>(i)] ? (span_rows[i] >> (z * kBlockCells)) & 0xff : (uio ? 0xff : 0);
        live |= bits << (i * kBlockCells);
      }
      if (live == 0) {
        std::fill(layer, layer + kBlockCells * kBlockCells, cap);
        continue;
      }
    }
    for (int yy = first - d; yy < first + kBlockCells + d; ++yy) {
      const T* block = values->span[static_cast<size_t>(yy >> kBlockShift)];
      rows[yy] = block ? block + ((z << (2 * kBlockShift)) | ((yy & (kBlockCells - 1)) << kBlockShift)) : outside_row;
    }
    for (int y = 0; y < kBlockCells; ++y) {
      T* o = layer + (y << kBlockShift);
      if (by_row && ((live >> (first + y - d)) & reach_bits) == 0) {
        std::fill(o, o + kBlockCells, cap);
        continue;
      }
      const bool any = minPlusRows(rows + first + y - d, 0, values->add_rows.data(), 2 * d + 1, cap, o);
      finite_rows |= uint64_t{any} << (z * kBlockCells + y);
    }
  }
  rows_xy_[slot] = finite_rows;
}

// Pass 3: along z from pass 2, 8 cells (a row) at a time as pass 2, capped
// where distances saturate.
template <typename T>
void DistanceField::alongZ(const Eigen::Vector3i& b, PassValues<T>* values) {
  const int d = reach_cells_, first = reach_blocks_ * kBlockCells;
  const T cap = static_cast<T>(saturated_sq_);
  const size_t slot = slotOf(b);
  uint32_t* out = &cells_[slot * kBlockVolume];
  const uint8_t* classes = &classes_[slot * kBlockVolume];
  uint64_t* span_rows = values->span_rows.data();
  if (!gatherSpan(b, 2, values->xy, rows_xy_, &values->span, span_rows)) {
    for (int i = 0; i < kBlockVolume; ++i) out[i] = saturated_sq_ | (uint32_t{classes[i]} << kClassShift);
    return;
  }
  const bool uio = config_.unknown_is_occupied;
  constexpr int kLayer = kBlockCells * kBlockCells;
  T outside_layer[kLayer];
  std::fill(outside_layer, outside_layer + kLayer, uio ? T{0} : cap);
  const T** layers = values->rows.data();  // the span's layers, by their z in the span
  for (int zz = first - d; zz < first + kBlockCells + d; ++zz) {
    const T* block = values->span[static_cast<size_t>(zz >> kBlockShift)];
    layers[zz] = block ? block + ((zz & (kBlockCells - 1)) << (2 * kBlockShift)) : outside_layer;
  }
  // Per row y, bit zz: the span's layer zz holds a value below cap in that
  // row (pass 2's row bits transposed: bit 8 z + y to bit 8 y + z); all set
  // when the span does not fit a word.
  uint64_t live[kBlockCells];
  std::fill(live, live + kBlockCells, ~uint64_t{0});
  const bool by_row = reach_blocks_ <= kMaxBitReachBlocks;
  if (by_row) {
    std::fill(live, live + kBlockCells, 0);
    for (int i = 0; i <= 2 * reach_blocks_; ++i) {
      const uint64_t by_y = values->span[static_cast<size_t>(i)] ? transpose8(span_rows[i]) : (uio ? ~uint64_t{0} : 0);
      for (int y = 0; y < kBlockCells; ++y) live[y] |= ((by_y >> (y * kBlockCells)) & 0xff) << (i * kBlockCells);
    }
  }
  const uint64_t reach_bits = by_row ? (uint64_t{2} << (2 * d)) - 1 : 0;  // 2d + 1 layers, fewer than 64 by_row
  for (int z = 0; z < kBlockCells; ++z)
    for (int y = 0; y < kBlockCells; ++y) {
      const int row = y * kBlockCells;
      uint32_t* o = out + z * kLayer + row;
      const uint8_t* c = classes + z * kLayer + row;
      if (by_row && ((live[y] >> (first + z - d)) & reach_bits) == 0) {  // nothing within reach along z
        for (int x = 0; x < kBlockCells; ++x) o[x] = saturated_sq_ | (uint32_t{c[x]} << kClassShift);
        continue;
      }
      T acc[kBlockCells];
      minPlusRows(layers + first + z - d, static_cast<size_t>(row), values->add_rows.data(), 2 * d + 1, cap, acc);
      for (int x = 0; x < kBlockCells; ++x) o[x] = acc[x] | (uint32_t{c[x]} << kClassShift);
    }
}

// --- queries ------------------------------------------------------------------

DistanceSample DistanceField::sample(const Eigen::Vector3d& W_point) const {
  Eigen::Vector3i l;
  if (!localCell(W_point, &l)) return outsideSample();
  return sampleCell(l, cellIndex(l));
}

void DistanceField::sample(const Eigen::Vector3d* W_points, size_t count, DistanceSample* out) const {
  // A ring of the points ahead whose lines are requested: slot i mod
  // kPrefetchPoints holds point i's local cell until point i is answered.
  struct Ahead {
    Eigen::Vector3i l;
    size_t index;
    bool inside;
  };
  Ahead ahead[kPrefetchPoints];
  auto request = [&](size_t i) {
    Ahead& a = ahead[i % kPrefetchPoints];
    a.inside = localCell(W_points[i], &a.l);
    if (!a.inside) return;
    a.index = cellIndex(a.l);
    // The cell's line only: its neighbours along x and y mostly share it or
    // the next, and those along z are loaded side by side once its word has
    // arrived. Their indices here would cost branches that mispredict (a
    // random point's cell lies on a block's face along some axis often);
    // prefetching all seven lines was no faster than sample() one at a time.
    prefetchRead(&cells_[a.index]);
  };
  for (size_t i = 0; i < std::min(count, kPrefetchPoints); ++i) request(i);
  for (size_t i = 0; i < count; ++i) {
    const Ahead a = ahead[i % kPrefetchPoints];  // its slot takes point i + kPrefetchPoints next
    if (i + kPrefetchPoints < count) request(i + kPrefetchPoints);
    out[i] = a.inside ? sampleCell(a.l, a.index) : outsideSample();
  }
}

void DistanceField::sample(const std::vector<Eigen::Vector3d>& W_points, std::vector<DistanceSample>* out) const {
  out->resize(W_points.size());
  sample(W_points.data(), W_points.size(), out->data());
}

DistanceSample DistanceField::sampleCell(const Eigen::Vector3i& l, size_t index) const {
  DistanceSample s;
  s.in_window = true;
  const uint32_t word = cells_[index];  // one load: the class and the distance
  s.cell_class = static_cast<CellClass>(classOf(word));
  s.distance_m = distanceOf(word);
  if (sqOf(word) >= saturated_sq_) return s;  // flat: no gradient
  const float res = static_cast<float>(resolution_m_);
  for (int a = 0; a < 3; ++a) {  // central differences; one-sided at the window's edges
    float lo = s.distance_m, hi = s.distance_m;
    float cells = 0.0f;
    if (l[a] > 0) {
      lo = distanceOf(cells_[neighbourIndex(l, index, a, -1)]);
      cells += 1.0f;
    }
    if (l[a] + 1 < size_cells_[a]) {
      hi = distanceOf(cells_[neighbourIndex(l, index, a, +1)]);
      cells += 1.0f;
    }
    if (cells > 0.0f) s.gradient[a] = (hi - lo) / (cells * res);
  }
  return s;
}

bool DistanceField::clip(const Eigen::Vector3d& W_from, const Eigen::Vector3d& W_to, double* t_in,
                         double* t_out) const {
  const Eigen::AlignedBox3d box = window();
  const Eigen::Vector3d dir = W_to - W_from;
  double t0 = 0.0, t1 = 1.0;
  for (int a = 0; a < 3; ++a) {  // the slabs between the window's faces
    if (dir[a] == 0.0) {
      if (W_from[a] < box.min()[a] || W_from[a] > box.max()[a]) return false;
      continue;
    }
    double ta = (box.min()[a] - W_from[a]) / dir[a], tb = (box.max()[a] - W_from[a]) / dir[a];
    if (ta > tb) std::swap(ta, tb);
    t0 = std::max(t0, ta);
    t1 = std::min(t1, tb);
  }
  *t_in = t0;
  *t_out = t1;
  return t0 <= t1;
}

template <typename Visit>
bool DistanceField::walk(const Eigen::Vector3d& W_from, const Eigen::Vector3d& W_to, double t_in, double t_out,
                         Eigen::Vector3i* next_cell, Visit&& visit) const {
  const Eigen::Vector3d dir = W_to - W_from;
  const Eigen::Vector3i origin_cell = origin_block_ * kBlockCells;
  const Eigen::Vector3i top = size_cells_ - Eigen::Vector3i::Ones();
  auto cellAt = [&](double t) {  // on the window's faces the cell inside
    const Eigen::Vector3d p = (W_from + t * dir) / resolution_m_;
    return (p.array().floor().cast<int>().matrix() - origin_cell).cwiseMax(0).cwiseMin(top).eval();
  };
  Eigen::Vector3i cell = cellAt(t_in);
  const Eigen::Vector3i last = cellAt(t_out);
  // Amanatides & Woo: per axis the t of the next face crossed and the t per cell.
  Eigen::Vector3i step, remaining;
  Eigen::Vector3d t_max, t_delta;
  for (int a = 0; a < 3; ++a) {
    step[a] = dir[a] > 0.0 ? 1 : (dir[a] < 0.0 ? -1 : 0);
    remaining[a] = std::abs(last[a] - cell[a]);
    if (step[a] == 0) {
      t_max[a] = std::numeric_limits<double>::infinity();
      t_delta[a] = 0.0;
      continue;
    }
    const double face_m = (origin_cell[a] + cell[a] + (step[a] > 0 ? 1 : 0)) * resolution_m_;
    t_max[a] = (face_m - W_from[a]) / dir[a];
    t_delta[a] = resolution_m_ / std::abs(dir[a]);
  }
  double t = t_in;
  if (!visit(cell, t)) return false;
  // Exactly as many steps as faces between the first and the last cell:
  // the walk ends in the last cell whatever the rounding.
  for (int left = remaining.sum(); left > 0; --left) {
    int axis = -1;
    for (int a = 0; a < 3; ++a)
      if (remaining[a] > 0 && (axis < 0 || t_max[a] < t_max[axis])) axis = a;
    t = std::min(std::max(t, t_max[axis]), t_out);
    cell[axis] += step[axis];
    t_max[axis] += t_delta[axis];
    --remaining[axis];
    if (!visit(cell, t)) return false;
  }
  // The cell after the last one: across the face the segment crosses next.
  int axis = 0;
  for (int a = 1; a < 3; ++a)
    if (t_max[a] < t_max[axis]) axis = a;
  *next_cell = cell;
  (*next_cell)[axis] += step[axis];
  return true;
}

namespace {
void requireFinite(const Eigen::Vector3d& v, const char* what) {
  if (!v.allFinite()) throw std::invalid_argument(std::string("distance field: ") + what + " is NaN or infinite");
}
}  // namespace

PathCheckResult DistanceField::checkPath(const std::vector<Eigen::Vector3d>& W_waypoints, double radius_m,
                                         bool unknown_as_occupied) const {
  if (W_waypoints.empty() || W_waypoints.size() > kMaxWaypoints)
    throw std::invalid_argument("checkPath: " + std::to_string(W_waypoints.size()) + " waypoints; 1 to " +
                                std::to_string(kMaxWaypoints) + " are taken");
  if (!(radius_m >= 0.0 && radius_m <= config_.max_distance_m))
    throw std::invalid_argument("checkPath: the radius " + std::to_string(radius_m) + " m is not in [0, " +
                                std::to_string(config_.max_distance_m) + "] m (max_distance_m)");
  for (size_t i = 0; i < W_waypoints.size(); ++i)
    if (!W_waypoints[i].allFinite())
      throw std::invalid_argument("checkPath: waypoint " + std::to_string(i) + " is NaN or infinite");

  PathCheckResult result;
  long unknown_segment = -1;
  Eigen::Vector3d W_unknown = Eigen::Vector3d::Zero();
  double min_clearance_m = std::numeric_limits<double>::infinity();
  auto finish = [&](PathVerdict verdict) {
    result.verdict = verdict;
    result.min_clearance_m = std::isinf(min_clearance_m) ? 0.0 : min_clearance_m;
    if (verdict == PathVerdict::kUnknown) {
      result.first_segment = unknown_segment;
      result.W_point = W_unknown;
    }
    return result;
  };
  const size_t segments = std::max<size_t>(1, W_waypoints.size() - 1);
  for (size_t i = 0; i < segments; ++i) {
    const Eigen::Vector3d& a = W_waypoints[i];
    const Eigen::Vector3d& b = W_waypoints[std::min(i + 1, W_waypoints.size() - 1)];
    bool blocked = false;
    // Unknown at t along the segment: blocked if asked, else the first unknown point.
    auto unknownAt = [&](double t) {
      if (unknown_as_occupied) {
        blocked = true;
        result.first_segment = static_cast<long>(i);
        result.W_point = a + t * (b - a);
      } else if (unknown_segment < 0) {
        unknown_segment = static_cast<long>(i);
        W_unknown = a + t * (b - a);
      }
    };
    double t_in = 0.0, t_out = 1.0;
    const bool crosses = clip(a, b, &t_in, &t_out);
    if (!crosses || t_in > 0.0) unknownAt(0.0);  // it starts outside the window
    if (blocked) return finish(PathVerdict::kBlocked);
    if (!crosses) continue;
    Eigen::Vector3i next;
    walk(a, b, t_in, t_out, &next, [&](const Eigen::Vector3i& l, double t) {
      const uint32_t word = cells_[cellIndex(l)];
      const uint8_t cell_class = classOf(word);
      const bool known = cell_class != static_cast<uint8_t>(CellClass::kUnknown);
      const double d = distanceOf(word);
      if (known) min_clearance_m = std::min(min_clearance_m, d);
      if (cell_class == static_cast<uint8_t>(CellClass::kOccupied) || d < radius_m) {
        blocked = true;
        result.first_segment = static_cast<long>(i);
        result.W_point = a + t * (b - a);
        return false;
      }
      if (!known) unknownAt(t);
      return !blocked;
    });
    if (!blocked && t_out < 1.0) unknownAt(t_out);  // it leaves the window
    if (blocked) return finish(PathVerdict::kBlocked);
  }
  return finish(unknown_segment >= 0 ? PathVerdict::kUnknown : PathVerdict::kClear);
}

RayCastResult DistanceField::castRay(const Eigen::Vector3d& W_origin, const Eigen::Vector3d& W_direction,
                                     double max_range_m) const {
  requireFinite(W_origin, "castRay: the origin");
  requireFinite(W_direction, "castRay: the direction");
  if (!std::isfinite(max_range_m) || max_range_m < 0.0)
    throw std::invalid_argument("castRay: the range " + std::to_string(max_range_m) +
                                " m must be finite and not negative");
  const double norm = W_direction.norm();
  if (!(norm > 0.0) || !std::isfinite(norm)) throw std::invalid_argument("castRay: the direction is zero");
  const Eigen::Vector3d dir = W_direction / norm;
  const Eigen::Vector3d W_end = W_origin + dir * max_range_m;
  RayCastResult result;
  double t_in = 0.0, t_out = 1.0;
  if (!clip(W_origin, W_end, &t_in, &t_out) || t_in > 0.0) {  // the origin lies outside the window
    result.verdict = RayVerdict::kUnknown;
    result.W_point = ((W_origin / resolution_m_).array().floor() + 0.5).matrix() * resolution_m_;
    return result;
  }
  Eigen::Vector3i next;
  const bool walked = walk(W_origin, W_end, t_in, t_out, &next, [&](const Eigen::Vector3i& l, double t) {
    const uint8_t c = classOf(cells_[cellIndex(l)]);
    if (c == static_cast<uint8_t>(CellClass::kFree)) return true;
    result.verdict = c == static_cast<uint8_t>(CellClass::kOccupied) ? RayVerdict::kHit : RayVerdict::kUnknown;
    result.W_point = centreOf(l);
    result.range_m = t * max_range_m;
    return false;
  });
  if (!walked) return result;
  if (t_out < 1.0) {  // the window's edge before the range
    result.verdict = RayVerdict::kUnknown;
    result.W_point = centreOf(next);
    result.range_m = t_out * max_range_m;
    return result;
  }
  result.verdict = RayVerdict::kFree;
  result.W_point = W_end;
  result.range_m = max_range_m;
  return result;
}

void DistanceField::slice(double z_m, std::vector<Eigen::Vector3f>* W_centres, std::vector<float>* distances_m) const {
  W_centres->clear();
  distances_m->clear();
  const Eigen::AlignedBox3d box = window();
  if (!std::isfinite(z_m) || z_m < box.min().z() || z_m >= box.max().z()) return;
  const int lz = static_cast<int>(std::floor(z_m / resolution_m_)) - origin_block_.z() * kBlockCells;
  if (lz < 0 || lz >= size_cells_.z()) return;
  Eigen::Vector3i l(0, 0, lz);
  for (l.y() = 0; l.y() < size_cells_.y(); ++l.y())
    for (l.x() = 0; l.x() < size_cells_.x(); ++l.x()) {
      const uint32_t word = cells_[cellIndex(l)];
      if (classOf(word) == static_cast<uint8_t>(CellClass::kUnknown)) continue;
      W_centres->push_back(centreOf(l).cast<float>());
      distances_m->push_back(distanceOf(word));
    }
}

}  // namespace stereo_occupancy
