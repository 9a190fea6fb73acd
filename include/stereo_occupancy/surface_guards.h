#pragma once
/// @file
/// The surface profile's guards, a step of the drawing after its lines and
/// hits: next to what an image measured, a ray without a range says nothing
/// (sky guard, InverseSensorModelConfig::sky_guard_cells), nor does free
/// space beside it (edge guard, edge_guard_cells), and the gap in front of a
/// measurement says nothing only there (gap guard, gap_guard_cells).

#include <cstddef>
#include <cstdint>

#include <Eigen/Core>

#include "stereo_occupancy/local_grid.h"
#include "stereo_occupancy/worker_pool.h"

namespace stereo_occupancy {

/// Sets the cells of @p grid holding exactly @p value within @p radius cells
/// (Chebyshev) of an occupied cell (log-odds > 0) to 0, no information;
/// returns how many (none for @p value 0). With value = the sky's
/// log-odds: a ray that measured no range says nothing next to what the
/// image did measure. With a @p pool, slabs of z on its workers (or of y,
/// with @p occupied_blocks, where they share the flagged blocks out better):
/// the same grid and count. @p occupied_blocks as for applySurfaceGuards().
size_t silenceNearOccupied(LocalGrid* grid, float value, int radius, WorkerPool* pool = nullptr,
                           const uint8_t* occupied_blocks = nullptr);

/// Sets the cells holding 0 (no information) that lie farther than
/// @p radius cells (Chebyshev) from every occupied cell to @p free_value;
/// returns how many. With the surface profile's gap: the gap says nothing
/// next to what the image measured, and is free space elsewhere. With a
/// @p pool, on its workers: the same grid and count.
size_t freeZerosAwayFromOccupied(LocalGrid* grid, float free_value, int radius, WorkerPool* pool = nullptr);

/// The surface profile's guards for one image: the values its drawing
/// wrote and each guard's radius in cells (Chebyshev; 0: off).
struct SurfaceGuards {
  float sky_value = 0.0f;   ///< a ray without a range (LogOddsTable::skyLogOdds())
  int sky_radius = 0;       ///< InverseSensorModelConfig::sky_guard_cells
  float free_value = 0.0f;  ///< free space before the gap (LogOddsTable::freeLogOdds())
  int gap_radius = 0;       ///< InverseSensorModelConfig::gap_guard_cells
  int edge_radius = 0;      ///< InverseSensorModelConfig::edge_guard_cells
  /// The camera centre in the grid's cells (cell (i, j, k) spans [i, i + 1) × ...): the edge guard's view.
  Eigen::Vector3d grid_camera = Eigen::Vector3d::Zero();
};

/// The surface profile's guards at once, in one pass over the occupied
/// cells (and one over the grid for the gap guard):
/// - the gap guard: freeZerosAwayFromOccupied(free_value, gap_radius);
/// - the sky guard: silenceNearOccupied(sky_value, sky_radius);
/// - the edge guard: free space (free_value) within edge_radius of an
///   occupied cell says nothing, unless it lies in front of that cell as
///   the camera sees it (at least half a cell nearer along the ray through
///   its centre). A ray that passes beside a surface on its way to what lies
///   behind would call the surface's edge cells free, where the matcher's
///   disparities or the cells' corners put no hit; in front of a surface,
///   free space clears the noise hits of earlier views.
///
/// Returns the zeros set free (the gap guard). @p occupied_blocks, if given,
/// holds numBlocks() flags, set (nonzero) for every block that holds an
/// occupied cell (a drawer that knows where it put its hits:
/// LineDrawer::hitBlocks()): the guards then look only there, not at the
/// whole grid. The same grid and count on @p pool's workers.
size_t applySurfaceGuards(LocalGrid* grid, const SurfaceGuards& guards, WorkerPool* pool = nullptr,
                          const uint8_t* occupied_blocks = nullptr);

}  // namespace stereo_occupancy
