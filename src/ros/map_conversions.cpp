#include "stereo_occupancy/ros/map_conversions.h"

#include <sensor_msgs/point_cloud2_iterator.h>

#include <algorithm>
#include <array>
#include <cmath>
#include <functional>
#include <limits>
#include <sstream>
#include <streambuf>
#include <utility>

#include "stereo_occupancy/accumulating_octree.h"
#include "stereo_occupancy/map_accumulator.h"

namespace stereo_occupancy {

void toMsg(GridUpdate&& update, const std_msgs::Header& header, OccupancyUpdate* msg) {
  msg->header = header;
  msg->sensor_origin.x = update.W_sensor_origin.x();
  msg->sensor_origin.y = update.W_sensor_origin.y();
  msg->sensor_origin.z = update.W_sensor_origin.z();
  msg->resolution = update.resolution_m;
  for (int i = 0; i < 3; ++i) {
    msg->origin_index[i] = update.origin_index[i];
    msg->size[i] = static_cast<uint32_t>(update.size[i]);
  }
  // The arrays change hands; the cells are not copied.
  msg->run_start = std::move(update.run_start);
  msg->run_length = std::move(update.run_length);
  msg->log_odds = std::move(update.log_odds);
}

bool viewOf(const OccupancyUpdate& msg, GridUpdateView* view, std::string* why) {
  view->W_sensor_origin = Eigen::Vector3d(msg.sensor_origin.x, msg.sensor_origin.y, msg.sensor_origin.z);
  view->resolution_m = msg.resolution;
  for (int i = 0; i < 3; ++i) {
    if (msg.size[i] > static_cast<uint32_t>(std::numeric_limits<int>::max())) {
      if (why) *why = "grid size out of range";
      return false;
    }
    view->origin_index[i] = msg.origin_index[i];
    view->size[i] = static_cast<int>(msg.size[i]);
  }
  view->run_start = msg.run_start;
  view->run_length = msg.run_length;
  view->log_odds = msg.log_odds;
  return true;
}

namespace {
/// An output stream buffer that appends to a message's byte vector: the
/// octree's data is written once, into the message, with no string between.
class AppendToBytes : public std::streambuf {
 public:
  using Bytes = Octomap::_data_type;
  explicit AppendToBytes(Bytes* bytes) : bytes_(bytes) {}

 protected:
  int_type overflow(int_type c) override {
    if (!traits_type::eq_int_type(c, traits_type::eof())) bytes_->push_back(static_cast<Bytes::value_type>(c));
    return traits_type::not_eof(c);
  }
  std::streamsize xsputn(const char* s, std::streamsize n) override {
    const auto* first = reinterpret_cast<const Bytes::value_type*>(s);
    bytes_->insert(bytes_->end(), first, first + n);
    return n;
  }

 private:
  Bytes* bytes_;
};

/// An Octomap message of an OcTree of @p resolution_m whose data @p write
/// writes; @p bytes_bound, if not 0, is at least the data's size (one
/// allocation: a map's full data is its largest message).
void octomapMsg(double resolution_m, bool binary, const std_msgs::Header& header, size_t bytes_bound,
                const std::function<void(std::ostream&)>& write, Octomap* msg) {
  msg->header = header;
  msg->binary = binary;
  msg->id = "OcTree";
  msg->resolution = resolution_m;
  msg->data.clear();
  msg->data.reserve(bytes_bound);
  AppendToBytes buffer(&msg->data);
  std::ostream data(&buffer);
  write(data);
}
}  // namespace

void toMsg(const octomap::OcTree& tree, bool binary, const std_msgs::Header& header, Octomap* msg) {
  octomapMsg(
      tree.getResolution(), binary, header, 0,
      [&](std::ostream& out) {
        if (binary)
          tree.writeBinaryData(out);
        else
          tree.writeData(out);
      },
      msg);
}

void toMsg(const MapSnapshot& snapshot, bool binary, const std_msgs::Header& header, Octomap* msg) {
  octomapMsg(
      snapshot.resolution(), binary, header, snapshot.dataBytesBound(binary),
      [&](std::ostream& out) { snapshot.writeData(binary, out); }, msg);
}

std::unique_ptr<octomap::OcTree> treeFromMsg(const Octomap& msg) {
  if (msg.id != "OcTree" || !(msg.resolution > 0.0)) return nullptr;
  auto tree = std::make_unique<octomap::OcTree>(msg.resolution);
  std::stringstream data(std::string(msg.data.begin(), msg.data.end()));
  const bool read = static_cast<bool>(msg.binary ? tree->readBinaryData(data) : tree->readData(data));
  return read ? std::move(tree) : nullptr;
}

namespace {

/// Opacity of the free cells' markers: the occupied ones show through.
constexpr float kFreeMarkerAlpha = 0.25f;

/// rviz colour of a cell at height z: hue from blue (z_min) through green to
/// red (z_max), full saturation, as octomap_server colours its markers.
std_msgs::ColorRGBA heightColour(double z, double z_min, double z_max) {
  const double t = z_max > z_min ? std::clamp((z - z_min) / (z_max - z_min), 0.0, 1.0) : 0.5;
  const double hue = (1.0 - t) * 4.0;  // in units of 60 degrees: 0 red, 4 blue
  const float rising = static_cast<float>(1.0 - std::abs(std::fmod(hue, 2.0) - 1.0));
  std_msgs::ColorRGBA c;
  c.a = 1.0f;
  switch (std::min(static_cast<int>(hue), 3)) {
    case 0:
      c.r = 1.0f, c.g = rising;
      break;
    case 1:
      c.r = rising, c.g = 1.0f;
      break;
    case 2:
      c.g = 1.0f, c.b = rising;
      break;
    default:
      c.g = rising, c.b = 1.0f;
      break;
  }
  return c;
}

constexpr int kBlock = MapAccumulator::kBlockCells;

/// A block's marker id, from its x and y (the z goes into the namespace).
int blockMarkerId(const Eigen::Vector3i& b) {
  constexpr int kBlocksPerAxis = 65536 / kBlock;  // the key range in blocks
  return (b.x() + kBlocksPerAxis / 2) * kBlocksPerAxis + (b.y() + kBlocksPerAxis / 2);
}

/// The first and the last key of block @p b.
std::pair<octomap::OcTreeKey, octomap::OcTreeKey> blockKeys(const octomap::OcTree& tree, const Eigen::Vector3i& b) {
  const int offset = static_cast<int>(tree.coordToKey(0.0));  // key of global index 0
  auto key = [&](const Eigen::Vector3i& g) {
    return octomap::OcTreeKey(static_cast<octomap::key_type>(g.x() + offset),
                              static_cast<octomap::key_type>(g.y() + offset),
                              static_cast<octomap::key_type>(g.z() + offset));
  };
  const Eigen::Vector3i lo = b * kBlock;
  return {key(lo), key(lo + Eigen::Vector3i::Constant(kBlock - 1))};
}

/// Empties @p markers; for the whole map (@p all) a DELETEALL first.
void startBlockMarkers(bool all, const std_msgs::Header& header, visualization_msgs::MarkerArray* markers) {
  markers->markers.clear();
  if (!all) return;
  visualization_msgs::Marker clear;
  clear.header = header;
  clear.action = visualization_msgs::Marker::DELETEALL;
  markers->markers.push_back(clear);
}

}  // namespace

void blockMarkers(const octomap::OcTree& tree, const std::vector<Eigen::Vector3i>& blocks, bool all,
                  const std_msgs::Header& header, visualization_msgs::MarkerArray* markers) {
  double x0, y0, z_min, x1, y1, z_max;
  tree.getMetricMin(x0, y0, z_min);
  tree.getMetricMax(x1, y1, z_max);
  const int offset = static_cast<int>(tree.coordToKey(0.0));  // key of global index 0
  const unsigned depth = tree.getTreeDepth();
  const double c = tree.getResolution();
  startBlockMarkers(all, header, markers);
  for (const Eigen::Vector3i& b : blocks) {
    visualization_msgs::Marker m;
    m.header = header;
    m.ns = "occupied_cells_z" + std::to_string(b.z());
    m.id = blockMarkerId(b);
    m.type = visualization_msgs::Marker::CUBE_LIST;
    m.scale.x = m.scale.y = m.scale.z = c;
    m.pose.orientation.w = 1.0;
    m.color.a = 1.0f;
    // The block's keys; a coarse leaf gives the cells of it that the block holds.
    const auto [key_lo, key_hi] = blockKeys(tree, b);
    for (auto it = tree.begin_leafs_bbx(key_lo, key_hi), end = tree.end_leafs_bbx(); it != end; ++it) {
      if (!tree.isNodeOccupied(*it)) continue;
      const octomap::OcTreeKey first = it.getIndexKey();
      const int side = 1 << (depth - it.getDepth());
      for (int z = std::max<int>(first[2], key_lo[2]); z <= std::min<int>(first[2] + side - 1, key_hi[2]); ++z)
        for (int y = std::max<int>(first[1], key_lo[1]); y <= std::min<int>(first[1] + side - 1, key_hi[1]); ++y)
          for (int x = std::max<int>(first[0], key_lo[0]); x <= std::min<int>(first[0] + side - 1, key_hi[0]); ++x) {
            geometry_msgs::Point p;
            p.x = (x - offset + 0.5) * c;
            p.y = (y - offset + 0.5) * c;
            p.z = (z - offset + 0.5) * c;
            m.points.push_back(p);
            m.colors.push_back(heightColour(p.z, z_min, z_max));
          }
    }
    m.action = m.points.empty() ? visualization_msgs::Marker::DELETE : visualization_msgs::Marker::ADD;
    markers->markers.push_back(std::move(m));
  }
}

void freeBlockMarkers(const octomap::OcTree& tree, const std::vector<Eigen::Vector3i>& blocks, bool all,
                      const std_msgs::Header& header, visualization_msgs::MarkerArray* markers) {
  constexpr int kSizes = 5;  // leaf sides 1, 2, 4, 8, 16 cells
  static_assert(kBlock == 1 << (kSizes - 1), "one marker per leaf size up to the block's");
  const unsigned depth = tree.getTreeDepth();
  const double c = tree.getResolution();
  startBlockMarkers(all, header, markers);
  for (const Eigen::Vector3i& b : blocks) {
    std::array<visualization_msgs::Marker, kSizes> m;
    for (int s = 0; s < kSizes; ++s) {
      m[s].header = header;
      m[s].ns = "free_cells_z" + std::to_string(b.z()) + "_s" + std::to_string(1 << s);
      m[s].id = blockMarkerId(b);
      m[s].type = visualization_msgs::Marker::CUBE_LIST;
      m[s].scale.x = m[s].scale.y = m[s].scale.z = c * (1 << s);
      m[s].pose.orientation.w = 1.0;
      m[s].color.g = 1.0f;
      m[s].color.a = kFreeMarkerAlpha;
    }
    const auto [key_lo, key_hi] = blockKeys(tree, b);
    for (auto it = tree.begin_leafs_bbx(key_lo, key_hi), end = tree.end_leafs_bbx(); it != end; ++it) {
      if (tree.isNodeOccupied(*it) || !leafOverlaps(it, depth, key_lo, key_hi)) continue;
      const int side = 1 << (depth - it.getDepth());
      geometry_msgs::Point p;
      if (side >= kBlock) {  // the leaf covers the block: draw the block
        const Eigen::Vector3d centre = ((b * kBlock).cast<double>().array() + 0.5 * kBlock).matrix() * c;
        p.x = centre.x(), p.y = centre.y(), p.z = centre.z();
        m[kSizes - 1].points.push_back(p);
      } else {
        p.x = it.getX(), p.y = it.getY(), p.z = it.getZ();
        m[depth - it.getDepth()].points.push_back(p);
      }
    }
    for (auto& marker : m) {
      if (all && marker.points.empty()) continue;
      marker.action = marker.points.empty() ? visualization_msgs::Marker::DELETE : visualization_msgs::Marker::ADD;
      markers->markers.push_back(std::move(marker));
    }
  }
}

void toMsg(const ProjectedMap& map, const std_msgs::Header& header, nav_msgs::OccupancyGrid* msg) {
  msg->header = header;
  msg->info.map_load_time = header.stamp;
  msg->info.resolution = static_cast<float>(map.resolution_m);
  msg->info.width = static_cast<uint32_t>(map.width);
  msg->info.height = static_cast<uint32_t>(map.height);
  msg->info.origin.position.x = map.origin_x_m;
  msg->info.origin.position.y = map.origin_y_m;
  msg->info.origin.orientation.w = 1.0;
  msg->data = map.cells;
}

void occupiedCellCloud(const MapSnapshot& snapshot, const std_msgs::Header& header, sensor_msgs::PointCloud2* cloud) {
  cloud->header = header;
  sensor_msgs::PointCloud2Modifier modifier(*cloud);
  modifier.setPointCloud2FieldsByString(1, "xyz");
  modifier.resize(snapshot.numOccupied());
  sensor_msgs::PointCloud2Iterator<float> x(*cloud, "x"), y(*cloud, "y"), z(*cloud, "z");
  snapshot.forEachOccupiedCentre([&](const octomap::point3d& p) {
    *x = p.x();
    *y = p.y();
    *z = p.z();
    ++x, ++y, ++z;
  });
}

void occupiedCellCloud(const LocalGrid& grid, const std_msgs::Header& header, sensor_msgs::PointCloud2* cloud) {
  size_t n = 0;
  for (size_t i = 0; i < grid.numCells(); ++i) n += grid.data()[i] > 0.0f;
  cloud->header = header;
  sensor_msgs::PointCloud2Modifier modifier(*cloud);
  modifier.setPointCloud2Fields(4, "x", 1, sensor_msgs::PointField::FLOAT32, "y", 1, sensor_msgs::PointField::FLOAT32,
                                "z", 1, sensor_msgs::PointField::FLOAT32, "intensity", 1,
                                sensor_msgs::PointField::FLOAT32);
  modifier.resize(n);
  sensor_msgs::PointCloud2Iterator<float> x(*cloud, "x"), y(*cloud, "y"), z(*cloud, "z"), v(*cloud, "intensity");
  const Eigen::Vector3i& size = grid.size();
  for (int k = 0; k < size.z(); ++k)
    for (int j = 0; j < size.y(); ++j)
      for (int i = 0; i < size.x(); ++i) {
        const float value = grid.at(i, j, k);
        if (!(value > 0.0f)) continue;
        const Eigen::Vector3d p = grid.cellCentre(i, j, k);
        *x = static_cast<float>(p.x());
        *y = static_cast<float>(p.y());
        *z = static_cast<float>(p.z());
        *v = value;
        ++x, ++y, ++z, ++v;
      }
}

}  // namespace stereo_occupancy
