#include "stereo_occupancy/sim/map_evaluation.h"

#include <algorithm>
#include <cmath>
#include <limits>
#include <sstream>
#include <unordered_map>

#include "stereo_occupancy/local_grid.h"
#include "stereo_occupancy/sim/scene_images.h"

namespace stereo_occupancy {

ObservedGroundTruth observeGroundTruth(const FlightScenario& scenario, double resolution_m, double max_range_m,
                                       int frame_step, int pixel_step, int surface_pixel_step) {
  ObservedGroundTruth truth;
  if (surface_pixel_step <= 0) surface_pixel_step = pixel_step;
  truth.resolution_m = resolution_m;
  const StereoCameraModel camera(scenario.camera);
  const double c = resolution_m;
  for (size_t f = 0; f < scenario.T_W_B.size(); f += static_cast<size_t>(frame_step)) {
    const Eigen::Isometry3d T_W_C = scenario.cameraPose(f);
    truth.viewpoints.push_back(T_W_C.translation());
    for (int y = surface_pixel_step / 2; y < scenario.camera.height_px; y += surface_pixel_step) {
      for (int x = surface_pixel_step / 2; x < scenario.camera.width_px; x += surface_pixel_step) {
        const Eigen::Vector3d W_dir = T_W_C.linear() * camera.rayThroughPixel(x, y).normalized();
        const double range = scenario.scene.castRay(T_W_C.translation(), W_dir);
        // The cell just behind the hit point holds the solid (a point on a face
        // that the ray meets from the cell's far side belongs to the cell in front).
        if (range <= max_range_m)
          truth.surface.insert(packCell(LocalGrid::globalIndex(T_W_C.translation() + (range + 1e-6) * W_dir, c)));
      }
    }
    for (int y = pixel_step / 2; y < scenario.camera.height_px; y += pixel_step) {
      for (int x = pixel_step / 2; x < scenario.camera.width_px; x += pixel_step) {
        const Eigen::Vector3d W_dir = T_W_C.linear() * camera.rayThroughPixel(x, y).normalized();
        const double range = scenario.scene.castRay(T_W_C.translation(), W_dir);
        const double empty_until = std::min(range - 1.5 * c, max_range_m);
        for (double l = 0.5 * c; l < empty_until; l += 0.5 * c) {
          const Eigen::Vector3d p = T_W_C.translation() + l * W_dir;
          if (scenario.scene.distance(p) > 0.9 * c) truth.empty.insert(packCell(LocalGrid::globalIndex(p, c)));
        }
      }
    }
  }
  return truth;
}

std::vector<Eigen::Vector3i> frameSurfaceCells(const FlightScenario& scenario, size_t frame, double resolution_m,
                                               double max_range_m) {
  const StereoCameraModel camera(scenario.camera);
  const Eigen::Isometry3d T_W_C = scenario.cameraPose(frame);
  cv::Mat depth;
  renderTrueDisparity(scenario, frame, &depth);
  std::unordered_set<uint64_t> seen;
  std::vector<Eigen::Vector3i> cells;
  for (int y = 0; y < depth.rows; ++y)
    for (int x = 0; x < depth.cols; ++x) {
      const float z = depth.at<float>(y, x);
      if (!std::isfinite(z)) continue;  // sky
      const Eigen::Vector3d C_ray = camera.rayThroughPixel(x, y);
      const double range = z * C_ray.norm();
      if (range > max_range_m) continue;
      // Just behind the hit point, as in observeGroundTruth().
      const Eigen::Vector3d W_point = T_W_C * (C_ray * (z * (1.0 + 1e-6 / range)));
      const Eigen::Vector3i g = LocalGrid::globalIndex(W_point, resolution_m);
      if (seen.insert(packCell(g)).second) cells.push_back(g);
    }
  return cells;
}

size_t countCalledFree(const LocalGrid& grid, const std::vector<Eigen::Vector3i>& cells) {
  size_t called_free = 0;
  for (const Eigen::Vector3i& g : cells) {
    const Eigen::Vector3i local = g - grid.originIndex();
    if (!grid.contains(local)) continue;
    const float v = grid.at(local.x(), local.y(), local.z());
    called_free += v < 0.0f && v != LocalGrid::kUnknown;
  }
  return called_free;
}

std::string MapQuality::toJson() const {
  std::ostringstream out;
  out << "{\"occupied_cells\": " << occupied_cells << ", \"occupied_at_surface\": " << occupied_at_surface
      << ", \"occupied_phantom\": " << occupied_phantom << ", \"truth_surface_cells\": " << truth_surface_cells
      << ", \"surface_found\": " << surface_found << ", \"surface_called_free\": " << surface_called_free
      << ", \"truth_empty_cells\": " << truth_empty_cells << ", \"empty_known_free\": " << empty_known_free
      << ", \"occupied_precision\": " << occupiedPrecision() << ", \"occupied_recall\": " << occupiedRecall()
      << ", \"surface_called_free_fraction\": " << surfaceCalledFree() << ", \"free_coverage\": " << freeCoverage()
      << ", \"phantom_share\": " << phantomShare() << ", \"f1\": " << f1() << "}";
  return out.str();
}

std::string RangeBand::name() const {
  auto metres = [](double v) { return std::to_string(static_cast<int>(std::lround(v))); };
  return std::isfinite(max_m) ? metres(min_m) + "-" + metres(max_m) + " m" : metres(min_m) + "+ m";
}

std::vector<RangeBand> standardRangeBands() {
  return {{0.0, 10.0}, {10.0, 20.0}, {20.0, std::numeric_limits<double>::infinity()}};
}

namespace {
/// The centre of the cell with global index @p g [m].
Eigen::Vector3d cellCentre(const Eigen::Vector3i& g, double resolution_m) {
  return (g.cast<double>().array() + 0.5).matrix() * resolution_m;
}

/// @p map's node at the cell with global index @p g (cells of its resolution), or null.
const octomap::OcTreeNode* nodeAt(const octomap::OcTree& map, const Eigen::Vector3i& g) {
  const Eigen::Vector3d p = cellCentre(g, map.getResolution());
  return map.search(p.x(), p.y(), p.z());
}

/// Scores true surface cell @p g (a global index) into @p q: counted, called
/// free by its own node, found if an occupied node lies within one cell.
void scoreSurfaceCell(const octomap::OcTree& map, const Eigen::Vector3i& g, MapQuality* q) {
  ++q->truth_surface_cells;
  const octomap::OcTreeNode* own = nodeAt(map, g);
  if (own && !map.isNodeOccupied(own)) ++q->surface_called_free;
  bool found = false;
  for (int dz = -1; dz <= 1 && !found; ++dz)
    for (int dy = -1; dy <= 1 && !found; ++dy)
      for (int dx = -1; dx <= 1 && !found; ++dx) {
        const octomap::OcTreeNode* n = nodeAt(map, g + Eigen::Vector3i(dx, dy, dz));
        found = n && map.isNodeOccupied(n);
      }
  q->surface_found += found;
}
}  // namespace

MapQuality evaluateMap(const octomap::OcTree& map, const SyntheticScene& scene, const ObservedGroundTruth& truth,
                       const RangeBand& band) {
  MapQuality q;
  const double c = map.getResolution();
  const bool everything = band.min_m <= 0.0 && !std::isfinite(band.max_m);
  auto inBand = [&](const Eigen::Vector3d& p) {
    if (everything) return true;
    double nearest2 = std::numeric_limits<double>::infinity();
    for (const Eigen::Vector3d& v : truth.viewpoints) nearest2 = std::min(nearest2, (p - v).squaredNorm());
    return nearest2 >= band.min_m * band.min_m && nearest2 < band.max_m * band.max_m;
  };
  // Occupied leaves within one cell of a true surface (a leaf may be larger than one cell).
  for (auto it = map.begin_leafs(), end = map.end_leafs(); it != end; ++it) {
    if (!map.isNodeOccupied(*it)) continue;
    const Eigen::Vector3d centre(it.getX(), it.getY(), it.getZ());
    if (!inBand(centre)) continue;
    ++q.occupied_cells;
    const double half = 0.5 * it.getSize();
    const double tolerance = std::sqrt(3.0) * half + c;
    if (scene.distance(centre) <= tolerance)
      ++q.occupied_at_surface;
    else if (!scene.isInside(centre))
      ++q.occupied_phantom;
  }
  for (uint64_t key : truth.surface) {
    const Eigen::Vector3i g = unpackCell(key);
    if (inBand(cellCentre(g, c))) scoreSurfaceCell(map, g, &q);
  }
  for (uint64_t key : truth.empty) {
    const Eigen::Vector3i g = unpackCell(key);
    if (!inBand(cellCentre(g, c))) continue;
    ++q.truth_empty_cells;
    const octomap::OcTreeNode* n = nodeAt(map, g);
    q.empty_known_free += n && !map.isNodeOccupied(n);
  }
  return q;
}

size_t ObstacleZones::observedCount() const {
  return static_cast<size_t>(std::count_if(zones.begin(), zones.end(), [](const auto& z) { return !z.empty(); }));
}

namespace {
/// A cell holding the surface points of several objects.
constexpr int kSharedCell = -3;

/// The cells holding each box's and the ground's surface points seen through
/// the pixels of the frames, in range.
void collectSurfaces(const FlightScenario& scenario, double resolution_m, double max_range_m, int frame_step,
                     int pixel_step, std::vector<std::unordered_set<uint64_t>>* boxes,
                     std::unordered_set<uint64_t>* ground) {
  const StereoCameraModel camera(scenario.camera);
  boxes->assign(scenario.scene.boxes.size(), {});
  for (size_t f = 0; f < scenario.T_W_B.size(); f += static_cast<size_t>(frame_step)) {
    const Eigen::Isometry3d T_W_C = scenario.cameraPose(f);
    const PixelHits hits = castPixelRays(scenario.scene, camera, T_W_C);
    for (int y = pixel_step / 2; y < scenario.camera.height_px; y += pixel_step)
      for (int x = pixel_step / 2; x < scenario.camera.width_px; x += pixel_step) {
        const int object = hits.object.at<int>(y, x);
        const double range = hits.range_m.at<double>(y, x);
        if (object == SyntheticScene::kHitNothing || !(range <= max_range_m)) continue;
        const Eigen::Vector3d W_dir = T_W_C.linear() * camera.rayThroughPixel(x, y).normalized();
        // Just behind the hit point, as in observeGroundTruth().
        const uint64_t key =
            packCell(LocalGrid::globalIndex(T_W_C.translation() + (range + 1e-6) * W_dir, resolution_m));
        (object >= 0 ? (*boxes)[static_cast<size_t>(object)] : *ground).insert(key);
      }
  }
}
}  // namespace

ObstacleZones observeObstacles(const FlightScenario& scenario, double resolution_m, double max_range_m, int frame_step,
                               int pixel_step) {
  std::vector<std::unordered_set<uint64_t>> surfaces;
  std::unordered_set<uint64_t> ground;
  collectSurfaces(scenario, resolution_m, max_range_m, frame_step, pixel_step, &surfaces, &ground);
  std::unordered_map<uint64_t, int> owner;  // a surface cell's one object, or kSharedCell
  for (uint64_t key : ground) owner[key] = SyntheticScene::kHitGround;
  for (size_t k = 0; k < surfaces.size(); ++k)
    for (uint64_t key : surfaces[k]) {
      const auto [it, inserted] = owner.emplace(key, static_cast<int>(k));
      if (!inserted && it->second != static_cast<int>(k)) it->second = kSharedCell;
    }
  ObstacleZones result;
  result.resolution_m = resolution_m;
  result.zones.resize(surfaces.size());
  for (size_t k = 0; k < surfaces.size(); ++k) {
    std::unordered_set<uint64_t> zone;
    for (uint64_t key : surfaces[k]) {
      const Eigen::Vector3i g = unpackCell(key);
      for (int dz = -1; dz <= 1; ++dz)
        for (int dy = -1; dy <= 1; ++dy)
          for (int dx = -1; dx <= 1; ++dx) {
            const uint64_t n = packCell(g + Eigen::Vector3i(dx, dy, dz));
            const auto it = owner.find(n);
            if (it == owner.end() || it->second == static_cast<int>(k)) zone.insert(n);
          }
    }
    result.zones[k].assign(zone.begin(), zone.end());
    std::sort(result.zones[k].begin(), result.zones[k].end());  // the same order on every run
  }
  return result;
}

DetectionTracker::DetectionTracker(const ObstacleZones& zones, const SyntheticScene& scene)
    : zones_(zones), scene_(scene), detections_(zones.zones.size()) {
  for (size_t k = 0; k < zones.zones.size(); ++k)
    if (!zones.zones[k].empty()) pending_.push_back(k);
}

void DetectionTracker::update(const octomap::OcTree& map, long frame, const Eigen::Vector3d& W_camera) {
  const auto shows = [&](size_t k) {
    for (uint64_t key : zones_.zones[k]) {
      const octomap::OcTreeNode* n = nodeAt(map, unpackCell(key));
      if (n && map.isNodeOccupied(n)) return true;
    }
    return false;
  };
  for (auto it = pending_.begin(); it != pending_.end();) {
    if (!shows(*it)) {
      ++it;
      continue;
    }
    detections_[*it] = Detection{frame, scene_.boxes[*it].exteriorDistance(W_camera)};
    it = pending_.erase(it);
  }
}

DetectionSummary summarizeDetections(const ObstacleZones& zones, const std::vector<Detection>& mine,
                                     const std::vector<Detection>* reference, long frame_tolerance) {
  DetectionSummary s;
  std::vector<double> distances;
  for (size_t k = 0; k < zones.zones.size(); ++k) {
    if (zones.zones[k].empty()) continue;
    ++s.observed;
    const Detection& m = mine[k];
    if (m.detected()) distances.push_back(m.distance_m);
    if (!reference) continue;
    const Detection& r = (*reference)[k];
    s.later_than_reference += r.detected() && (!m.detected() || m.frame > r.frame + frame_tolerance);
    s.earlier_than_reference += m.detected() && (!r.detected() || r.frame > m.frame + frame_tolerance);
  }
  s.detected = distances.size();
  if (!distances.empty()) {
    std::sort(distances.begin(), distances.end());
    s.median_distance_m = distances[distances.size() / 2];
    s.min_distance_m = distances.front();
  }
  return s;
}

octomap::Pointcloud worldPointCloud(const cv::Mat& disparity, const StereoCameraModel& camera,
                                    const Eigen::Isometry3d& T_W_C) {
  CV_Assert(disparity.type() == CV_32FC1);
  octomap::Pointcloud cloud;
  for (int y = 0; y < disparity.rows; ++y) {
    const float* row = disparity.ptr<float>(y);
    for (int x = 0; x < disparity.cols; ++x) {
      const float d = row[x];
      if (!(d > 0.0f) || !camera.isValidDisparity(d)) continue;
      const Eigen::Vector3d W_p = T_W_C * camera.pointFromDisparity(x, y, d);
      cloud.push_back(static_cast<float>(W_p.x()), static_cast<float>(W_p.y()), static_cast<float>(W_p.z()));
    }
  }
  return cloud;
}

std::unordered_set<uint64_t> surfaceCells(const std::vector<Eigen::Vector3d>& W_points, double resolution_m) {
  std::unordered_set<uint64_t> cells;
  for (const Eigen::Vector3d& p : W_points) cells.insert(packCell(LocalGrid::globalIndex(p, resolution_m)));
  return cells;
}

MapQuality evaluateAgainstSurface(const octomap::OcTree& map, const std::unordered_set<uint64_t>& surface,
                                  const std::function<bool(const Eigen::Vector3d&)>& counted) {
  MapQuality q;
  const double c = map.getResolution();
  auto nearSurface = [&](const Eigen::Vector3i& g) {
    for (int dz = -1; dz <= 1; ++dz)
      for (int dy = -1; dy <= 1; ++dy)
        for (int dx = -1; dx <= 1; ++dx)
          if (surface.count(packCell(g + Eigen::Vector3i(dx, dy, dz)))) return true;
    return false;
  };
  for (auto it = map.begin_leafs(), end = map.end_leafs(); it != end; ++it) {
    if (!map.isNodeOccupied(*it)) continue;
    const int cells = std::max(1, static_cast<int>(std::lround(it.getSize() / c)));
    const Eigen::Vector3d corner = Eigen::Vector3d(it.getX(), it.getY(), it.getZ()).array() - 0.5 * it.getSize();
    for (int z = 0; z < cells; ++z)
      for (int y = 0; y < cells; ++y)
        for (int x = 0; x < cells; ++x) {
          const Eigen::Vector3d centre = corner + (Eigen::Vector3d(x, y, z).array() + 0.5).matrix() * c;
          if (!counted(centre)) continue;
          ++q.occupied_cells;
          q.occupied_at_surface += nearSurface(LocalGrid::globalIndex(centre, c));
        }
  }
  for (uint64_t key : surface) scoreSurfaceCell(map, unpackCell(key), &q);
  return q;
}

}  // namespace stereo_occupancy
