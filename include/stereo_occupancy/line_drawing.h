#pragma once
/// @file
/// Line drawing (Andert 2009, section V-A) and pyramidal line drawing
/// (section VI-B): each valid pixel's ray is traversed through the grid and
/// every cell on it gets L̂(s(l)) (eq. 11), keeping the larger value where lines
/// overlap (obstacle priority).

#include <Eigen/Geometry>
#include <opencv2/core.hpp>

#include <cstdint>
#include <limits>
#include <vector>

#include "stereo_occupancy/disparity_pyramid.h"
#include "stereo_occupancy/draw_statistics.h"
#include "stereo_occupancy/inverse_sensor_model.h"
#include "stereo_occupancy/local_grid.h"
#include "stereo_occupancy/stereo_camera_model.h"
#include "stereo_occupancy/worker_pool.h"

namespace stereo_occupancy {

/// Instruction sets the line drawing's free run uses.
enum class SimdLevel {
  kScalar,  ///< plain C++ (every target)
  kSse2,    ///< two cells at a time (every x86-64 CPU)
  kNeon,    ///< two cells at a time (every aarch64 CPU)
};
/// The level's name: "scalar", "sse2" or "neon".
const char* toString(SimdLevel level);

/// The best level this target offers (the default of DrawingConfig::simd).
SimdLevel availableSimdLevel();
/// True for kScalar and for availableSimdLevel().
bool isAvailable(SimdLevel level);

/// Up to this many keys stableOrderAscending() orders by rank, without branches.
constexpr int kRankOrderedKeys = 24;
/// @p order[0 .. count) = the indices of @p keys (no NaN) by ascending key,
/// equal keys in their index order (a stable sort's order). The bounded
/// pyramid's hole test orders a span's leaves with it.
void stableOrderAscending(const float* keys, int count, int* order);

/// Draws disparity images into a LocalGrid by line drawing. Holds references
/// to the camera, the lookup tables and the grid; not thread-safe (but it
/// may draw one image on several threads: setWorkers()).
class LineDrawer {
 public:
  /// @param simd the free run's instruction set; one this target lacks (isAvailable()) gives availableSimdLevel().
  LineDrawer(const StereoCameraModel& camera, const LogOddsTable& table, const PyramidLevelTable& levels,
             SimdLevel simd = availableSimdLevel());

  /// The instruction set the free runs use.
  SimdLevel simdLevel() const { return simd_; }
  /// Draws each image with @p pool's workers (null: on the calling thread).
  /// The grid is the same bit for bit for any number of workers: each draws
  /// its share of the blocks into a grid of its own, and a cell keeps the
  /// largest value (obstacle priority does not depend on the order).
  void setWorkers(WorkerPool* pool) { pool_ = pool; }
  /// With the surface profile, draws the bounded descent's spans (below) as
  /// spans (true, the default) or descends into them (false: for tests and
  /// benchmarks; the same occupied cells, more free ones, more lines).
  void setSurfaceSpans(bool on) { surface_spans_ = on; }
  /// Grids of more cells are drawn on one thread (a worker's grid would cost too much memory).
  static constexpr size_t kMaxSharedGridCells = size_t{16} << 20;
  /// Cells the workers' own grids hold between images (they follow the
  /// grids drawn, and let go of what one rare huge grid needed).
  size_t workerCellsHeld() const {
    size_t cells = 0;
    for (const auto& g : worker_grids_) cells += g.capacity();
    return cells;
  }
  /// After drawImage(), drawPyramid() or drawPyramidBounded(): one flag per
  /// block of the grid drawn (LocalGrid::numBlocks()), nonzero where a line
  /// put its point hit (empty without point hits: the paper's profile).
  /// With the surface profile, whose table holds no occupied value, these
  /// are the blocks of all the grid's occupied cells
  /// (applySurfaceGuards() need look nowhere else).
  const std::vector<uint8_t>& hitBlocks() const { return hit_blocks_; }
  /// Pyramid blocks per worker a pyramid's descent is split into: enough to share the work evenly.
  static constexpr int kPartsPerWorker = 16;

  /// Section V-A: one line per valid pixel of a CV_32FC1 disparity image.
  void drawImage(const cv::Mat& disparity, const Eigen::Isometry3d& T_W_C, LocalGrid* grid, DrawStatistics* stats);

  /// Section VI-B: recursive descent through a min-disparity pyramid (eq. 14)
  /// from its top level; a pixel is drawn at level i when its disparity's
  /// level (eq. 13) is >= i, or when i is the lowest level (eq. 15 below 0).
  void drawPyramid(const DisparityPyramid& min_pyramid, const Eigen::Isometry3d& T_W_C, LocalGrid* grid,
                   DrawStatistics* stats);

  /// Bounded pyramidal line drawing (beyond the paper): as drawPyramid(), but
  /// a block is drawn at level i only if @p bound says its disparities, from
  /// @p min_pyramid and @p max_pyramid of the same image, are represented
  /// faithfully by one line at the block's minimum; otherwise the descent
  /// goes on to its four children. A near obstacle in a block (a post before
  /// a far wall, a wire against the sky) thus keeps its own lines. A block
  /// that descends draws the free stretch its children share once (along its
  /// centre ray, up to its nearest measurement's front and to the depth
  /// where its level's rays are one cell apart); its children start there.
  ///
  /// With the surface profile a block whose rays lie within one cell of each
  /// other up to its farthest measurement (eq. 13) and whose depths leave no
  /// hole wider than one measurement's gap (oblique ground: a span) is not
  /// descended: one line along its centre ray draws the free space up to its
  /// nearest measurement's gap; the free space beyond it, within one cell of
  /// the surface, is left out (docs/performance.md has what the spans cost
  /// and save). The lines draw no hits: every pixel that measures a range
  /// gives its own, in the cell drawImage() gives it (drawPixelHits()), so
  /// the occupied cells are per-pixel line drawing's exactly. (One hit per
  /// block, at its farthest disparity, lost the nearer surface where a real
  /// matcher's disparities in a block spread over more than a cell of
  /// depth.)
  void drawPyramidBounded(const DisparityPyramid& min_pyramid, const DisparityPyramid& max_pyramid,
                          const DisparityBlockBound& bound, const Eigen::Isometry3d& T_W_C, LocalGrid* grid,
                          DrawStatistics* stats);

  /// Draws the ray from the camera centre along the unit direction W_dir with
  /// the profile of one measurement, over the ranges [l_begin, l_stop] up to
  /// min(profile end, max range). Returns the number of cells written; parts
  /// of the ray outside the grid are skipped.
  uint64_t drawRay(const Eigen::Vector3d& W_origin, const Eigen::Vector3d& W_dir, const RangeProfile& profile,
                   LocalGrid* grid, double l_begin = 0.0,
                   double l_stop = std::numeric_limits<double>::infinity()) const;

 private:
  /// The grid as the lines see it while one image is drawn into it: the
  /// camera centre in the grid's cell units, its cells and the range limit.
  /// Built once per image, not once per line.
  struct RayGrid {
    Eigen::Vector3d g0;            ///< line origin relative to the grid's lower corner [cells]
    Eigen::Vector3d W_origin;      ///< the camera centre [m]
    Eigen::Vector3i origin_index;  ///< global index of the grid's first cell
    double c = 0.0;                ///< cell size [m]
    double inv_c = 0.0;            ///< 1 / c [1/m]
    double max_range_m = 0.0;
    Eigen::Vector3i size;
    int64_t stride[3] = {0, 0, 0};  ///< index steps along x, y, z
    float* data = nullptr;
    uint8_t* hit_blocks = nullptr;  ///< hitBlocks() of the grid drawn, or null: hits not flagged
    int64_t blocks_per_row = 0;     ///< LocalGrid::blocksPerRow()
    /// A line whose ends lie in [kMargin, upper) on every axis lies inside the grid [cells].
    static constexpr double kMargin = 1e-3;
    double upper[3] = {0.0, 0.0, 0.0};  ///< size - kMargin [cells]
  };
  RayGrid rayGrid(const Eigen::Vector3d& W_origin, LocalGrid* grid) const;
  /// rayGrid() for an image: its hits flag their blocks in hitBlocks(), all 0 at first.
  RayGrid imageGrid(const Eigen::Vector3d& W_origin, LocalGrid* grid);
  /// drawRay() in a RayGrid without the surface profile's point hit: the
  /// lines of pixels and blocks draw it from the measured depth instead
  /// (drawHitAtDepth()).
  uint64_t drawLine(const RayGrid& g, const Eigen::Vector3d& W_dir, const RangeProfile& profile, double l_begin,
                    double l_stop) const;

  /// What stays fixed during one (bounded or plain) descent.
  /// A block the workers descend from, and the depth its lines start at.
  struct PartStart {
    int x, y;
    double z_begin;
  };
  struct Descent {
    const DisparityPyramid& min_pyramid;
    const DisparityPyramid* max_pyramid;  ///< bounded descent only
    const DisparityBlockBound* bound;     ///< bounded descent only
    const Eigen::Isometry3d& T_W_C;
    RayGrid grid;
    RangeProfile free_profile;  ///< of the pixels that measure no range
    double cell_f_m_px;         ///< c·f: level i's rays are one cell apart at depth c·f / 2^i
    DrawStatistics* stats;
    /// When set, a descent that reaches split_level records the block
    /// (a part for the workers) instead of descending into it.
    std::vector<PartStart>* parts = nullptr;
    int split_level = 0;
    /// The surface profile's hits come from drawPixelHits(), every pixel's
    /// (the bounded descent): the blocks' lines and spans draw none.
    bool pixel_hits = false;
  };
  Descent descent(const DisparityPyramid& min_pyramid, const DisparityPyramid* max_pyramid,
                  const DisparityBlockBound* bound, const Eigen::Isometry3d& T_W_C, LocalGrid* grid,
                  DrawStatistics* stats);

  /// The surface profile's point hit of every pixel of rows [y_begin,
  /// y_end) of @p disparity that measures a range, each where drawImage()'s
  /// pixel line put it before: in the cell of T_W_C·(z·C_ray) (eqs. 1, 2).
  /// Returns the cells written; adds the pixels to @p stats (if not null).
  uint64_t drawPixelHits(const RayGrid& g, const cv::Mat& disparity, int y_begin, int y_end,
                         const Eigen::Matrix3d& R_W_C, DrawStatistics* stats) const;
  /// Bands of image rows per worker that drawPixelHits() is split into.
  static constexpr int kHitBandsPerWorker = 4;
  /// pixelProfile() with the ray's norm at hand (|p_c| / z_c, eq. 2) and the free profile built once.
  RangeProfile profileOf(const Descent& s, double ray_norm, float d_px) const;
  /// Draws the line of pixel (x, y) at pyramid level i with disparity d, from depth z_begin on.
  uint64_t drawPixel(const Descent& s, int level, int x, int y, float d_px, double z_begin = 0.0) const;
  void descend(const Descent& s, int level, int x, int y) const;
  /// Calls draw_part(part, g, stats) for each part in [0, parts) on the
  /// workers, each with @p g on its own grid and its own counters, then
  /// merges their grids into @p grid (which @p g is) and adds the counters to @p stats.
  template <typename DrawPart>
  void drawParts(size_t parts, const RayGrid& g, LocalGrid* grid, DrawStatistics* stats, const DrawPart& draw_part);
  /// The workers that draw into @p grid: 1 without a pool or for a grid too large to copy.
  unsigned workersFor(const LocalGrid& grid) const;
  /// The pyramid's level whose blocks are the workers' parts: the highest
  /// with at least kPartsPerWorker blocks per worker (or the lowest level).
  int splitLevel(const DisparityPyramid& pyramid, unsigned workers) const;
  /// Descends the pyramid @p s from its top on the workers; @p descend_from(s, level, x, y, z_begin) is the descent.
  template <typename DescendFrom>
  void drawPyramidParts(const Descent& s, LocalGrid* grid, DrawStatistics* stats, const DescendFrom& descend_from);
  /// Each used worker grid into @p grid by max, and back to kUnknown.
  void mergeWorkerGrids(const std::vector<PerWorker<char>>& used, LocalGrid* grid);
  /// The ray through the centre of block (x, y) of a pyramid level, z = 1.
  Eigen::Vector3d blockRay(int level, int x, int y) const;
  void descendBounded(const Descent& s, int level, int x, int y, double z_begin) const;
  /// The sub-blocks a bounded descent would draw one line each for (its leaves).
  struct SpanLeaves {
    static constexpr int kMaxLeaves = 64;  ///< more: the block is descended
    int count = 0;
    float lo[kMaxLeaves], hi[kMaxLeaves];  ///< a leaf's min and max disparity [px]
    float hull_lo = 0.0f, hull_hi = 0.0f;  ///< the leaves' smallest lo and largest hi [px]
    /// Each leaf, in the order gathered, overlaps the hull of the leaves
    /// before it or leaves a faithful gap to it.
    bool chained = true;
    /// Extends the hull by the next leaf, [lo, hi], before it is added.
    void chain(const DisparityBlockBound& bound, float lo, float hi);
  };
  /// Adds the leaves below a block; false if one is sky (its free line to the
  /// range is needed) or there are more than kMaxLeaves.
  bool gatherLeaves(const Descent& s, int level, int x, int y, SpanLeaves* out) const;
  /// True if the block is a span: its leaves measure depths with no hole
  /// wider than one measurement's gap (oblique ground, not a post before a wall).
  bool isSpan(const Descent& s, int level, int x, int y, SpanLeaves* leaves) const;
  /// A span: free space along its centre ray up to the nearest measurement's
  /// gap (its pixels' hits are drawPixelHits()').
  void drawSpan(const Descent& s, int level, int x, int y, float d_max, double z_begin) const;

  const StereoCameraModel& camera_;
  const LogOddsTable& table_;
  const PyramidLevelTable& levels_;
  SimdLevel simd_;
  bool surface_spans_ = true;
  WorkerPool* pool_ = nullptr;
  std::vector<std::vector<float>> worker_grids_;         ///< worker w >= 1 draws into [w - 1]; kUnknown between images
  std::vector<uint8_t> hit_blocks_;                      ///< hitBlocks()
  std::vector<std::vector<uint8_t>> worker_hit_blocks_;  ///< worker w >= 1 flags its hits' blocks in [w - 1]
};

}  // namespace stereo_occupancy
