#pragma once
/// @file
/// An incremental Euclidean distance field over a window around the vehicle,
/// for planners: distance to the nearest occupied cell (up to a maximum)
/// with its gradient, a flag for unknown space, path checks and ray casts.
/// Not in the paper. Fed by the accumulator's fusion (the cells whose class
/// each fused update changed, MapAccumulator::takeClassChanges()), never by a
/// second fusion of the same updates.

#include <octomap/OcTree.h>

#include <functional>

#include <Eigen/Core>
#include <Eigen/Geometry>  // AlignedBox3d

#include <cmath>
#include <cstddef>
#include <cstdint>
#include <new>  // bad_alloc
#include <string>
#include <vector>

#include "stereo_occupancy/cell_class.h"  // CellClass, CellClassChange
#include "stereo_occupancy/parameter_table.h"

namespace stereo_occupancy {

/// Parameters of the distance field.
struct DistanceFieldConfig {
  bool enabled = true;               ///< maintain the field at all
  double window_xy_m = 50.0;         ///< window edge along x and y, centred on the vehicle [m]
  double window_z_m = 10.0;          ///< window edge along z [m]
  double max_distance_m = 2.0;       ///< distances saturate here; path checks take radii up to it [m]
  bool unknown_is_occupied = false;  ///< unknown cells are obstacles of the field (distances to them)

  /// The parameters (parameter_table.h): f(spec, member) for each.
  template <typename Self, typename F>
  static void forEachParameter(Self& c, F&& f) {
    f(textParameter("distance_field", "maintain the distance field around the vehicle (services, slice)"), c.enabled);
    f(numberParameter("distance_window_xy_m", "m", 1.0, 1000.0, "the field's window edge along x and y"),
      c.window_xy_m);
    f(numberParameter("distance_window_z_m", "m", 1.0, 1000.0, "the field's window edge along z"), c.window_z_m);
    f(numberParameter("max_distance_m", "m", 0.1, 20.0, "distances saturate here; the largest path-check radius"),
      c.max_distance_m);
    f(textParameter("unknown_is_occupied", "unknown cells count as obstacles of the field"), c.unknown_is_occupied);
  }
  /// The ranges of forEachParameter().
  bool isValid(std::string* why = nullptr) const { return parametersInRange(*this, why); }
};

/// One point's answer.
struct DistanceSample {
  bool in_window = false;  ///< false: outside the window; the rest says unknown
  CellClass cell_class = CellClass::kUnknown;
  /// Distance from the centre of the point's cell to the centre of the
  /// nearest obstacle cell, exact; max_distance_m if none is nearer [m].
  /// NaN outside the window.
  float distance_m = 0.0f;
  /// Central differences of distance_m over the neighbouring cells [m/m];
  /// zero where the distance saturates or outside the window.
  Eigen::Vector3f gradient = Eigen::Vector3f::Zero();
};

/// A path check's verdict.
enum class PathVerdict : uint8_t {
  kClear = 0,    ///< every cell along the path is known and at least the radius from any obstacle
  kBlocked = 1,  ///< a cell along it lies nearer than the radius to an obstacle (or is unknown, if asked)
  kUnknown = 2,  ///< not blocked, but it crosses unknown space or leaves the window
};

/// A path check's answer.
struct PathCheckResult {
  PathVerdict verdict = PathVerdict::kUnknown;
  /// Index of the first segment (waypoints i and i + 1) that is blocked, or
  /// that is unknown if none is blocked; -1 when clear.
  long first_segment = -1;
  Eigen::Vector3d W_point = Eigen::Vector3d::Zero();  ///< where that segment first is blocked / unknown [m]
  double min_clearance_m = 0.0;                       ///< smallest distance along the known part of the path [m]
};

/// A ray cast's verdict.
enum class RayVerdict : uint8_t {
  kHit = 0,      ///< an occupied cell within the range
  kFree = 1,     ///< known free up to the range
  kUnknown = 2,  ///< unknown space (or the window's edge) before any occupied cell
};

/// A ray cast's answer.
struct RayCastResult {
  RayVerdict verdict = RayVerdict::kUnknown;
  Eigen::Vector3d W_point = Eigen::Vector3d::Zero();  ///< centre of the occupied / first unknown cell [m]
  double range_m = 0.0;                               ///< distance along the ray to where it entered that cell [m]
};

namespace detail {

/// On Linux, arrays of at least this size are 2 MiB-aligned and advised to
/// be backed by transparent huge pages (madvise); elsewhere, and smaller
/// arrays, come from operator new [bytes].
constexpr size_t kHugePageBytes = size_t{2} << 20;
/// @p bytes of memory, huge pages where the OS gives them (see kHugePageBytes).
/// @throws std::bad_alloc
void* allocateHugePages(size_t bytes);
/// Frees what allocateHugePages(@p bytes) returned.
void freeHugePages(void* p, size_t bytes);

/// A std allocator on allocateHugePages(): the field's cells, read at random
/// places of the window by the queries, then take one TLB entry per 2 MiB
/// instead of per 4 KiB page.
template <typename T>
struct HugePageAllocator {
  using value_type = T;
  HugePageAllocator() = default;
  template <typename U>
  HugePageAllocator(const HugePageAllocator<U>& /*other*/) {}
  T* allocate(size_t n) {
    if (n > static_cast<size_t>(-1) / sizeof(T)) throw std::bad_alloc();
    return static_cast<T*>(allocateHugePages(n * sizeof(T)));
  }
  void deallocate(T* p, size_t n) { freeHugePages(p, n * sizeof(T)); }
};
template <typename T, typename U>
bool operator==(const HugePageAllocator<T>& /*a*/, const HugePageAllocator<U>& /*b*/) {
  return true;
}
template <typename T, typename U>
bool operator!=(const HugePageAllocator<T>& /*a*/, const HugePageAllocator<U>& /*b*/) {
  return false;
}

}  // namespace detail

/// The field. Not thread-safe: callers serialise updates and queries
/// (ros/distance_field_server.h shares one between the accumulator and
/// planners in the same process).
class DistanceField {
 public:
  /// Largest number of waypoints checkPath() takes.
  static constexpr size_t kMaxWaypoints = 100000;

  /// Edge of the blocks the window moves by and the updates recompute [cells].
  static constexpr int kBlockCells = 8;
  /// Largest window (cells; 4 bytes of distance, 1 of class and 4 or 8 of
  /// scratch each): the window's edges are rounded up to whole blocks.
  static constexpr size_t kMaxWindowCells = size_t{1} << 26;

  /// @throws std::invalid_argument if @p config is not valid,
  /// @p resolution_m is not positive, or the window would hold more than
  /// kMaxWindowCells cells at that resolution.
  DistanceField(const DistanceFieldConfig& config, double resolution_m);

  const DistanceFieldConfig& config() const { return config_; }
  double resolution() const { return resolution_m_; }

  /// Brings the field up to date after a fused update: re-centres the window
  /// on @p W_vehicle (in whole blocks; the cells that enter are read from
  /// @p map), applies @p changes and recomputes the distances they can
  /// change. @p all: the map changed everywhere (load, reset):
  /// the window is read from @p map again. Work follows the changes.
  /// A NaN / infinite @p W_vehicle leaves the window where it is.
  /// Cells outside the window count as unknown: obstacles if
  /// unknown_is_occupied (cells near the window's edge are then near an
  /// obstacle), else not (distances near the edge ignore what lies beyond).
  /// Reads @p map's leaves only: its inner nodes may lag
  /// (MapAccumulator::leafTree()).
  /// @throws std::invalid_argument if @p map's resolution is not the field's.
  void update(const octomap::OcTree& map, const std::vector<CellClassChange>& changes, bool all,
              const Eigen::Vector3d& W_vehicle) {
    update(map, changes, {}, all, W_vehicle);
  }
  /// The same with @p regions, boxes in which the map changed otherwise
  /// (MapAccumulator::takeClassChanges()): the window's blocks they overlap
  /// are read from @p map again after @p changes are applied; a region
  /// outside the window costs nothing.
  void update(const octomap::OcTree& map, const std::vector<CellClassChange>& changes,
              const std::vector<CellBox>& regions, bool all, const Eigen::Vector3d& W_vehicle);
  /// The map as update() gets it: called with the box of cells (global
  /// indices) the field is about to read, whose leaves must then be current,
  /// so that the caller makes only those current (MapAccumulator's cache:
  /// MapAccumulator::leafTree(const CellBox&)). Called only when the field
  /// reads cells (the window placed or moved, regions inside it, all): first
  /// with an empty box, before the field changes, for the map's resolution
  /// and threshold; then once per box read (the window when placed, a slab
  /// per axis when it moves, a region's blocks).
  using MapSource = std::function<const octomap::OcTree&(const CellBox& cells)>;
  /// update() from @p map, asked only for the cells read.
  /// @throws std::invalid_argument if @p map's resolution is not the field's (the field unchanged).
  void update(const MapSource& map, const std::vector<CellClassChange>& changes, const std::vector<CellBox>& regions,
              bool all, const Eigen::Vector3d& W_vehicle);

  /// The window's box in the map's frame [m].
  Eigen::AlignedBox3d window() const;

  /// The answer at @p W_point (metres, map frame); outside the window or at
  /// a NaN point, in_window is false and the point is unknown.
  DistanceSample sample(const Eigen::Vector3d& W_point) const;

  /// sample() at each of the @p count points @p W_points (metres, map
  /// frame) into @p out[0, count), the same answers bit for bit. For many
  /// points scattered over the window: the cache line of the cell
  /// kPrefetchPoints points ahead is requested while the present point is
  /// answered, so that the misses overlap instead of following one another.
  /// @p W_points and @p out may be null when @p count is 0.
  void sample(const Eigen::Vector3d* W_points, size_t count, DistanceSample* out) const;
  /// The same for a vector; @p out is resized to W_points.size().
  void sample(const std::vector<Eigen::Vector3d>& W_points, std::vector<DistanceSample>* out) const;

  /// How many points ahead the batch sample() requests the point's cell:
  /// a point takes about 45 ns when its cells are cached, so 8 ahead cover a
  /// miss to memory of up to 350 ns; 16 were slower under load, 4 no faster.
  static constexpr size_t kPrefetchPoints = 8;

  /// Checks the straight segments between @p W_waypoints for a body of
  /// radius @p radius_m: each cell the segments pass through must be known
  /// and at least radius_m from the nearest obstacle (cell centres), and not
  /// occupied itself (radius 0). One waypoint: its cell, as segment 0.
  /// Blocked: the walk stops at the first blocked cell (min_clearance_m up
  /// to it); W_point is where the segment enters the first blocked or
  /// unknown cell (or leaves the window). Work: at most the window's
  /// cells along each segment (the parts outside it are unknown).
  /// The waypoints are counted before anything is read or allocated.
  /// @throws std::invalid_argument for fewer than 1 or more than
  /// kMaxWaypoints waypoints, a NaN / infinite waypoint, a negative radius or
  /// one above max_distance_m.
  PathCheckResult checkPath(const std::vector<Eigen::Vector3d>& W_waypoints, double radius_m,
                            bool unknown_as_occupied) const;

  /// Walks from @p W_origin along @p W_direction (any length) up to
  /// @p max_range_m through the cells: the first occupied cell is a hit, the
  /// first unknown cell or the window's edge (the first cell beyond it) is
  /// unknown; an origin outside the window is unknown at range 0.
  /// @throws std::invalid_argument for a NaN / infinite input, a zero
  /// direction, or a negative range.
  RayCastResult castRay(const Eigen::Vector3d& W_origin, const Eigen::Vector3d& W_direction, double max_range_m) const;

  /// Cell centres and distances of the window's cells in the horizontal
  /// layer that holds height @p z_m (known cells only), for a slice.
  void slice(double z_m, std::vector<Eigen::Vector3f>* W_centres, std::vector<float>* distances_m) const;

  /// Cells whose distance the last update() recomputed (for the summary lines).
  size_t lastUpdatedCells() const { return last_updated_cells_; }
  /// Cells the last update() read from the map: the blocks that entered the
  /// window, the blocks of the regions, or the whole window.
  size_t lastReadCells() const { return last_read_cells_; }

 private:
  /// Cells are stored block by block (kBlockCells^3 each, x fastest inside),
  /// blocks in a ring per axis: global block b lives in slot b mod n, so a
  /// move rewrites only the blocks that enter. "Local" indices count from
  /// the window's lowest cell / block.
  static constexpr int kBlockShift = 3;
  static constexpr int kBlockVolume = kBlockCells * kBlockCells * kBlockCells;
  static_assert(kBlockCells == 1 << kBlockShift, "blocks are 2^kBlockShift cells");

  size_t slotOf(const Eigen::Vector3i& local_block) const {
    int s[3];
    for (int a = 0; a < 3; ++a) {
      s[a] = local_block[a] + ring_phase_[a];
      if (s[a] >= size_blocks_[a]) s[a] -= size_blocks_[a];
    }
    return static_cast<size_t>(s[0]) + static_cast<size_t>(size_blocks_[0]) * (s[1] + size_blocks_[1] * s[2]);
  }
  /// Index of the local cell @p l (inside the window) in classes_ and cells_.
  size_t cellIndex(const Eigen::Vector3i& l) const {
    const size_t in_block =
        static_cast<size_t>(((l.z() & (kBlockCells - 1)) << (2 * kBlockShift)) |
                            ((l.y() & (kBlockCells - 1)) << kBlockShift) | (l.x() & (kBlockCells - 1)));
    return slotOf(Eigen::Vector3i(l.x() >> kBlockShift, l.y() >> kBlockShift, l.z() >> kBlockShift)) * kBlockVolume +
           in_block;
  }
  bool inside(const Eigen::Vector3i& l) const {
    return (l.array() >= 0).all() && (l.array() < size_cells_.array()).all();
  }
  bool isObstacle(uint8_t cell_class) const {
    return cell_class == static_cast<uint8_t>(CellClass::kOccupied) ||
           (config_.unknown_is_occupied && cell_class == static_cast<uint8_t>(CellClass::kUnknown));
  }
  /// A cell's word in cells_: its squared distance below kClassShift, its class above.
  static constexpr int kClassShift = 30;
  static constexpr uint32_t kSqMask = (uint32_t{1} << kClassShift) - 1;
  static uint32_t sqOf(uint32_t word) { return word & kSqMask; }
  static uint8_t classOf(uint32_t word) { return static_cast<uint8_t>(word >> kClassShift); }
  /// Distance of a cell's word [m].
  float distanceOf(uint32_t word) const {
    const uint32_t sq = sqOf(word);
    return sq >= saturated_sq_ ? static_cast<float>(config_.max_distance_m)
                               : std::sqrt(static_cast<float>(sq)) * static_cast<float>(resolution_m_);
  }
  /// sample()'s answer at the local cell @p l (inside the window) whose word is cells_[@p index].
  DistanceSample sampleCell(const Eigen::Vector3i& l, size_t index) const;
  /// Index in cells_ of the neighbour @p step (-1 or +1) along @p axis of the
  /// local cell @p l at @p index; the neighbour must be inside the window.
  size_t neighbourIndex(const Eigen::Vector3i& l, size_t index, int axis, int step) const {
    const int in_block = l[axis] & (kBlockCells - 1);
    if (in_block + step >= 0 && in_block + step < kBlockCells) {  // same block: a stride away
      const size_t stride = size_t{1} << (axis * kBlockShift);
      return step > 0 ? index + stride : index - stride;
    }
    Eigen::Vector3i n = l;  // across a block face: the other block's slot
    n[axis] += step;
    return cellIndex(n);
  }
  /// The local cell of @p W_point, or false outside the window (or NaN).
  bool localCell(const Eigen::Vector3d& W_point, Eigen::Vector3i* l) const;
  Eigen::Vector3d centreOf(const Eigen::Vector3i& l) const;

  // update()'s steps.
  Eigen::Vector3i wantedOrigin(const Eigen::Vector3d& W_vehicle) const;
  /// @throws std::invalid_argument if @p map's resolution is not the field's.
  void checkResolution(const octomap::OcTree& map) const;
  /// The window's cells (global indices), and those of a window at @p origin_block.
  CellBox windowCells() const { return windowCellsAt(origin_block_); }
  CellBox windowCellsAt(const Eigen::Vector3i& origin_block) const;
  void moveTo(const MapSource& map, const Eigen::Vector3i& origin_block);
  void readAll(const MapSource& map);
  /// Reads the local blocks [lo, hi) that entered from @p map and marks them (markEntered()).
  void readBlocks(const MapSource& map, const Eigen::Vector3i& lo, const Eigen::Vector3i& hi);
  /// Sets the local blocks [lo, hi) unknown and reads their classes from @p map (asked for their cells).
  void readClasses(const MapSource& map, const Eigen::Vector3i& lo, const Eigen::Vector3i& hi);
  /// Reads the window's blocks that @p cells overlaps from @p map again;
  /// those that held or hold what the outside does not are changed.
  void readRegion(const MapSource& map, const CellBox& cells);
  /// Marks the blocks [lo, hi) that entered: computed, and the ones that
  /// differ from the outside (differsFromOutside()) changed.
  void markEntered(const Eigen::Vector3i& lo, const Eigen::Vector3i& hi);
  /// The block in @p slot holds a cell whose obstacle status is not the
  /// outside's (an obstacle; a free cell if unknown is occupied).
  bool differsFromOutside(size_t slot) const;
  /// The slot of a global block index (inside the window or not).
  size_t globalSlot(const Eigen::Vector3i& global_block) const;
  void applyChanges(const std::vector<CellClassChange>& changes);
  void markChanged(const Eigen::Vector3i& local_block);
  /// Marks the local blocks [lo, hi) for recomputation (without dilation).
  void markRecompute(const Eigen::Vector3i& lo, const Eigen::Vector3i& hi);
  void recompute();
  /// The separable transform's values [cells^2], each capped at
  /// saturated_sq_ (which also says "no obstacle within reach"), and the
  /// passes' scratch, in lanes of T: 16 bits while saturated_sq_ is at most
  /// kMaxNarrowSq (a value plus a squared offset then fits a signed 16-bit
  /// lane: twice the lanes per instruction of 32 bits, half the memory;
  /// SSE2 has a 16-bit min, not a 32-bit one), else 32 bits.
  template <typename T>
  struct PassValues {
    std::vector<T> x;                 ///< pass 1: squared distance along x
    std::vector<T> xy;                ///< pass 2: in the xy plane
    std::vector<T> add_rows;          ///< row i (8 lanes): (i - reach_cells_)^2, what passes 2 and 3 add
    std::vector<const T*> span;       ///< passes 2, 3: the blocks within reach along the pass's axis (null outside)
    std::vector<uint64_t> span_rows;  ///< passes 2, 3: their row bits (rows_x_, rows_xy_)
    std::vector<const T*> rows;       ///< passes 2, 3: the span's rows (pass 2) or layers (pass 3), cell by cell
  };
  static constexpr uint32_t kMaxNarrowSq = 16383;
  template <typename T>
  void allocatePasses(size_t cells, PassValues<T>* values);
  template <typename T>
  void runPasses(PassValues<T>* values);
  template <typename T>
  void alongX(const Eigen::Vector3i& local_block, std::vector<T>* out);  // pass 1
  template <typename T>
  void alongXScalar(const Eigen::Vector3i& local_block, std::vector<T>* out);
  /// Pass 1 takes a row's span as one 64-bit word up to this reach [blocks].
  static constexpr int kMaxBitReachBlocks = 3;
  template <typename T>
  void alongY(const Eigen::Vector3i& local_block, PassValues<T>* values);  // pass 2
  template <typename T>
  void alongZ(const Eigen::Vector3i& local_block, PassValues<T>* values);  // pass 3 into cells_
  /// Points @p span at the blocks of @p values within the reach of block
  /// @p b along @p axis (null outside the window) and @p span_rows at their
  /// bits of @p rows (rows_x_ or rows_xy_; 0 outside); false if none of them
  /// holds a value below saturated_sq_ and the outside holds none.
  template <typename T>
  bool gatherSpan(const Eigen::Vector3i& b, int axis, const std::vector<T>& values, const std::vector<uint64_t>& rows,
                  std::vector<const T*>* span, uint64_t* span_rows) const;
  Eigen::Vector3i blockOfLinear(int linear) const;
  int linearOfBlock(const Eigen::Vector3i& b) const {
    return b.x() + size_blocks_.x() * (b.y() + size_blocks_.y() * b.z());
  }

  /// The part [t_in, t_out] of the segment @p W_from -> @p W_to (t in
  /// [0, 1]) inside the window; false if none.
  bool clip(const Eigen::Vector3d& W_from, const Eigen::Vector3d& W_to, double* t_in, double* t_out) const;
  /// Walks the cells the segment's part [t_in, t_out] (clip()) passes
  /// through (3D DDA, Amanatides & Woo), calling visit(local cell, t where
  /// the segment enters it) until it returns false (then false). At the end
  /// @p next_cell is the cell the segment would enter after the last one.
  template <typename Visit>
  bool walk(const Eigen::Vector3d& W_from, const Eigen::Vector3d& W_to, double t_in, double t_out,
            Eigen::Vector3i* next_cell, Visit&& visit) const;

  DistanceFieldConfig config_;
  double resolution_m_;
  size_t last_updated_cells_ = 0;
  size_t last_read_cells_ = 0;

  Eigen::Vector3i size_blocks_;   ///< the window's edge [blocks]
  Eigen::Vector3i size_cells_;    ///< the window's edge [cells]
  Eigen::Vector3i origin_block_;  ///< global block index of the window's lowest block
  Eigen::Vector3i ring_phase_;    ///< slot of the window's lowest block: origin_block_ mod size_blocks_
  bool placed_ = false;           ///< an update() has placed the window
  /// Squared distances at or above it read as max_distance_m [cells^2].
  uint32_t saturated_sq_ = 0;
  int reach_cells_ = 0;             ///< largest offset along one axis to an obstacle that is not saturated [cells]
  int reach_blocks_ = 0;            ///< reach_cells_ in blocks, rounded up
  float occupied_log_odds_ = 0.0f;  ///< the map's threshold (update())
  std::vector<uint8_t> classes_;    ///< CellClass of each cell, for the passes and the reads (8 a word)
  /// Per cell, what the queries read in one load: the squared distance to
  /// the nearest obstacle, capped at saturated_sq_ [cells^2] (sqOf()), and
  /// the class, as in classes_ (classOf()).
  /// Huge pages where the OS gives them (detail::HugePageAllocator).
  std::vector<uint32_t, detail::HugePageAllocator<uint32_t>> cells_;
  bool narrow_ = false;                 ///< saturated_sq_ <= kMaxNarrowSq: the passes run in narrow_values_
  PassValues<uint16_t> narrow_values_;  ///< (scratch)
  PassValues<uint32_t> wide_values_;    ///< (scratch)
  std::vector<uint8_t> row_span_;       ///< pass 1: one row's obstacle flags with the reach on both sides (scratch)
  std::vector<const uint8_t*> span_blocks_;  ///< pass 1: the class blocks of that span (scratch)
  /// Per block, bit 8 z + y: the row (y, z) of pass 1's / pass 2's values
  /// holds one below saturated_sq_ (an obstacle within reach), so that
  /// passes 2 and 3 skip the blocks, and the rows, far from any.
  std::vector<uint64_t> rows_x_, rows_xy_;
  std::vector<uint8_t> region_differed_;  ///< readRegion(): per block, differsFromOutside() before the read (scratch)
  // The blocks of one update (local linear indices) and their marks (mark == epoch_: in the list).
  uint32_t epoch_ = 0;
  bool everything_ = false;  ///< this update recomputes the whole window
  std::vector<uint32_t> changed_mark_, mark_x_, mark_y_, mark_z_;
  std::vector<int> changed_, blocks_x_, blocks_y_, blocks_z_;
};

}  // namespace stereo_occupancy
