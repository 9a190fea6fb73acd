#include "stereo_occupancy/grid_update.h"

#include <cmath>
#include <cstring>
#include <limits>

namespace stereo_occupancy {

bool GridUpdateView::isConsistent(std::string* why) const {
  auto fail = [why](const std::string& text) {
    if (why) *why = text;
    return false;
  };
  if (!(std::isfinite(resolution_m) && resolution_m > 0.0)) return fail("resolution is not finite and > 0");
  if (!W_sensor_origin.allFinite()) return fail("sensor origin is not finite");
  if ((size.array() < 0).any()) return fail("negative grid size");
  const uint64_t cells = static_cast<uint64_t>(size.x()) * size.y() * size.z();
  if (cells > std::numeric_limits<uint32_t>::max()) return fail("grid too large for 32-bit cell indices");
  for (int a = 0; a < 3; ++a)  // every global index origin_index + local fits an int
    if (int64_t{origin_index[a]} + size[a] > std::numeric_limits<int>::max())
      return fail("the grid reaches beyond the 32-bit index range");
  if (run_start.size() != run_length.size()) return fail("run_start and run_length differ in length");
  uint64_t total = 0, end = 0;
  for (size_t k = 0; k < run_start.size(); ++k) {
    if (run_start[k] < end) return fail("runs overlap or are not sorted");
    end = static_cast<uint64_t>(run_start[k]) + run_length[k];
    if (end > cells) return fail("a run ends outside the grid");
    total += run_length[k];
  }
  if (total != log_odds.size())
    return fail("the runs cover " + std::to_string(total) + " cells but " + std::to_string(log_odds.size()) +
                " values came");
  // Finite: the exponent bits not all set. One pass without an early exit (vectorisable).
  uint32_t not_finite = 0;
  for (float v : log_odds) {
    uint32_t bits;
    std::memcpy(&bits, &v, sizeof bits);
    not_finite |= static_cast<uint32_t>((bits & 0x7f800000u) == 0x7f800000u);
  }
  if (not_finite != 0) return fail("a log-odds value is not finite");
  return true;
}

void encodeGridUpdate(const LocalGrid& grid, const Eigen::Vector3d& W_sensor_origin, GridUpdate* update) {
  update->W_sensor_origin = W_sensor_origin;
  update->resolution_m = grid.resolution();
  update->origin_index = grid.originIndex();
  update->size = grid.size();
  update->run_start.clear();
  update->run_length.clear();
  update->log_odds.clear();
  releaseIfOversized(&update->log_odds, grid.numCells());
  releaseIfOversized(&update->run_start, grid.numCells() / 2);
  releaseIfOversized(&update->run_length, grid.numCells() / 2);
  const float* data = grid.data();
  const size_t n = grid.numCells();
  auto informative = [](float v) { return v != LocalGrid::kUnknown && v != 0.0f; };
  size_t i = 0;
  while (i < n) {
    while (i + kInformationBlock <= n && !blockHasInformation(data + i)) i += kInformationBlock;  // empty space
    while (i < n && !informative(data[i])) ++i;
    if (i == n) break;
    const size_t start = i;
    while (i < n && informative(data[i])) ++i;
    update->log_odds.insert(update->log_odds.end(), data + start, data + i);
    update->run_start.push_back(static_cast<uint32_t>(start));
    update->run_length.push_back(static_cast<uint32_t>(i - start));
  }
}

}  // namespace stereo_occupancy
