#pragma once
/// @file
/// The surface profile's guards, a step of the drawing after its lines and
/// hits: next to what an image measured, a ray without a range says nothing
/// (sky guard, InverseSensorModelConfig::sky_guard_cells), and the gap in
/// front of a measurement says nothing only there (gap guard,
/// InverseSensorModelConfig::gap_guard_cells).

#include <cstddef>
#include <cstdint>

#include "stereo_occupancy/local_grid.h"
#include "stereo_occupancy/worker_pool.h"

namespace stereo_occupancy {

/// Sets the cells of @p grid holding exactly @p value within @p radius cells
/// (Chebyshev) of an occupied cell (log-odds > 0) to 0, no information;
/// returns how many (none for @p value 0). With value = the sky's
/// log-odds: a ray that measured no range says nothing next to what the
/// image did measure. With a @p pool, slabs of z on its workers: the same
/// grid and count. @p occupied_blocks as for applySurfaceGuards().
size_t silenceNearOccupied(LocalGrid* grid, float value, int radius, WorkerPool* pool = nullptr,
                           const uint8_t* occupied_blocks = nullptr);

/// Sets the cells holding 0 (no information) that lie farther than
/// @p radius cells (Chebyshev) from every occupied cell to @p free_value;
/// returns how many. With the surface profile's gap: the gap says nothing
/// next to what the image measured, and is free space elsewhere. With a
/// @p pool, on its workers: the same grid and count.
size_t freeZerosAwayFromOccupied(LocalGrid* grid, float free_value, int radius, WorkerPool* pool = nullptr);

/// The surface profile's two guards at once: freeZerosAwayFromOccupied(
/// @p free_value, @p gap_radius), then silenceNearOccupied(@p sky_value,
/// @p sky_radius), the same grid in one pass over the occupied cells and
/// one over the grid. Returns the zeros set free; a radius of 0 is that
/// guard off. @p occupied_blocks, if given, holds numBlocks() flags, set
/// (nonzero) for every block that holds an occupied cell (a drawer that
/// knows where it put its hits: LineDrawer::hitBlocks()): the guards then
/// look only there, not at the whole grid. The same grid and count.
size_t applySurfaceGuards(LocalGrid* grid, float sky_value, int sky_radius, float free_value, int gap_radius,
                          WorkerPool* pool = nullptr, const uint8_t* occupied_blocks = nullptr);

}  // namespace stereo_occupancy
