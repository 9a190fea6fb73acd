// libFuzzer target: arbitrary occupancy updates, as any node on the ROS graph
// may publish them, into the accumulator. Nothing may crash, no allocation
// may follow the box an update claims (libFuzzer's -malloc_limit_mb catches
// one that does), and a refused update must leave the map as it was.

#include <cstdint>
#include <cstdlib>
#include <cstring>
#include <sstream>

#include "stereo_occupancy/grid_update.h"
#include "stereo_occupancy/map_accumulator.h"

namespace so = stereo_occupancy;

namespace {

/// Reads the fuzzer's bytes as typed fields; zeros when they run out.
class Reader {
 public:
  Reader(const uint8_t* data, size_t size) : data_(data), size_(size) {}
  template <typename T>
  T next() {
    T value{};
    if (pos_ + sizeof(T) <= size_) std::memcpy(&value, data_ + pos_, sizeof(T));
    pos_ += sizeof(T);
    return value;
  }
  bool more() const { return pos_ < size_; }

 private:
  const uint8_t* data_;
  size_t size_;
  size_t pos_ = 0;
};

std::string serialised(const octomap::OcTree& tree) {
  std::ostringstream out;
  tree.write(out);
  return out.str();
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  Reader in(data, size);
  so::GridUpdate u;
  u.resolution_m = (in.next<uint8_t>() & 1) ? 0.25 : static_cast<double>(in.next<float>());
  // Mostly small boxes near the origin (so that some updates are taken),
  // sometimes anything at all.
  const uint8_t mode = in.next<uint8_t>();
  for (int a = 0; a < 3; ++a) {
    if (mode & 1) {
      u.origin_index[a] = in.next<int32_t>();
      u.size[a] = static_cast<int>(in.next<uint32_t>() & 0x7fffffffu);
    } else {
      u.origin_index[a] = in.next<int8_t>();
      u.size[a] = in.next<uint8_t>() % 24;
    }
  }
  for (int a = 0; a < 3; ++a)
    u.W_sensor_origin[a] = (mode & 2) ? static_cast<double>(in.next<float>()) : 0.25 * (u.origin_index[a] + 1.0);
  const int runs = in.next<uint8_t>() % 32;
  uint32_t at = 0;
  for (int k = 0; k < runs && in.more(); ++k) {
    const uint32_t gap = (mode & 4) ? in.next<uint32_t>() : in.next<uint8_t>();
    const uint32_t length = (mode & 8) ? in.next<uint32_t>() : in.next<uint8_t>() % 16;
    at += gap;
    u.run_start.push_back(at);
    u.run_length.push_back(length);
    at += length;
    for (uint32_t i = 0; i < length && i < 4096; ++i) u.log_odds.push_back(in.next<int8_t>() * 0.05f);
  }
  if (mode & 16) u.log_odds.push_back(in.next<float>());  // sometimes one value too many, or NaN

  so::MapAccumulatorConfig config;
  config.max_extent_m = 20.0;
  so::MapAccumulator map(config);
  so::GridUpdate seed;  // one good cell first, so that a refusal has something to leave alone
  seed.resolution_m = 0.25;
  seed.size = Eigen::Vector3i(1, 1, 1);
  seed.W_sensor_origin = Eigen::Vector3d(0.1, 0.1, 0.1);
  seed.run_start = {0};
  seed.run_length = {1};
  seed.log_odds = {1.0f};
  if (!map.integrate(seed)) std::abort();
  const std::string before = serialised(map.tree());
  if (!map.integrate(u) && serialised(map.tree()) != before) std::abort();  // a refusal changed the map
  map.prune();
  return 0;
}
