#include "stereo_occupancy/ros/parameters.h"

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <set>
#include <sstream>
#include <type_traits>

namespace stereo_occupancy {

namespace {
bool fail(std::string* why, const std::string& text) {
  if (why) *why = text;
  return false;
}
}  // namespace

bool DisparityMapperParameters::isValid(std::string* why) const {
  if (world_frame.empty()) return fail(why, "world_frame must not be empty");
  if (!parametersInRange(*this, why)) return false;
  if (!(camera.max_range_m > camera.min_range_m)) return fail(why, "max_range_m must be > min_range_m");
  return drawing.isValid(why);
}

bool OctomapAccumulatorParameters::isValid(std::string* why) const {
  if (!parametersInRange(*this, why) || !saving.isValid(why)) return false;
  if (!map_file.empty() && world_frame.empty()) return fail(why, "a map_file needs a world_frame (its frame)");
  return publisher.isValid(why) && map.isValid(why) && distance.isValid(why);
}

bool parseWaypoints(const std::string& text, std::vector<Eigen::Vector3d>* W_waypoints, std::string* why) {
  W_waypoints->clear();
  std::stringstream waypoints(text);
  for (std::string one; std::getline(waypoints, one, ';');) {
    if (one.find_first_not_of(" \t\n") == std::string::npos) continue;  // a trailing ';'
    for (char& c : one)
      if (c == ',') c = ' ';
    std::istringstream numbers(one);
    Eigen::Vector3d p;
    std::string rest;
    if (!(numbers >> p.x() >> p.y() >> p.z()) || (numbers >> rest))
      return fail(why, "waypoints: '" + one + "' is not three numbers x y z");
    if (!p.allFinite()) return fail(why, "waypoints: '" + one + "' is not finite");
    if (W_waypoints->size() >= DistanceField::kMaxWaypoints)
      return fail(why, "waypoints: more than " + std::to_string(DistanceField::kMaxWaypoints));
    W_waypoints->push_back(p);
  }
  if (W_waypoints->empty()) return fail(why, "waypoints: none given ('x y z; x y z; ...')");
  return true;
}

bool PathWatcherParameters::isValid(std::string* why) const {
  if (accumulator.empty()) return fail(why, "accumulator must name the accumulator nodelet");
  if (!parametersInRange(*this, why)) return false;
  std::vector<Eigen::Vector3d> parsed;
  return parseWaypoints(waypoints, &parsed, why);
}

namespace {

/// Reads parameters by the table through read(name, std::string* text) for
/// choices and read(name, T* value) for the rest, where T is double, int,
/// bool or std::string; each leaves the value unchanged when the source does
/// not have the name. Names a choice it cannot parse.
template <class Source>
class TableReader {
 public:
  explicit TableReader(Source& source) : source_(source) {}

  template <typename T>
  void operator()(const ParameterSpec& spec, T& value) {
    if constexpr (std::is_same_v<T, DrawingAlgorithm>) {
      std::string name = toString(value);
      source_(spec.name, &name);
      if (!parseDrawingAlgorithm(name, &value))
        note(std::string("algorithm must be one of ") + drawingAlgorithmNames() + " (got '" + name + "')");
    } else if constexpr (std::is_same_v<T, SensorProfile>) {
      std::string name = toString(value);
      source_(spec.name, &name);
      if (!parseSensorProfile(name, &value)) note("sensor_profile must be gaussian or surface (got '" + name + "')");
    } else if constexpr (std::is_same_v<T, uint64_t>) {  // ROS parameters are 32-bit ints
      int v = static_cast<int>(std::min<uint64_t>(value, INT32_MAX));
      source_(spec.name, &v);
      value = v > 0 ? static_cast<uint64_t>(v) : 0;
    } else {
      source_(spec.name, &value);
    }
  }
  /// The first choice that could not be parsed; empty if none.
  const std::string& error() const { return error_; }

 private:
  void note(const std::string& text) {
    if (error_.empty()) error_ = text;
  }
  Source& source_;
  std::string error_;
};

template <class Params, class Source>
bool readParameters(Source& source, Params* p, std::string* why) {
  TableReader<Source> reader(source);
  Params::forEachParameter(*p, reader);
  if (!reader.error().empty()) return fail(why, reader.error());
  return p->isValid(why);
}

/// Reads from name=value pairs; remembers which names it was asked for and
/// values it could not parse.
class PairReader {
 public:
  explicit PairReader(const std::map<std::string, std::string>& values) : values_(values) {}

  template <class T>
  void operator()(const char* name, T* value) {
    asked_.insert(name);
    const auto it = values_.find(name);
    if (it == values_.end()) return;
    T parsed = *value;
    if (parse(it->second, &parsed))
      *value = parsed;
    else if (error_.empty())
      error_ = std::string(name) + ": cannot read '" + it->second + "'";
  }
  const std::set<std::string>& asked() const { return asked_; }
  const std::string& error() const { return error_; }

 private:
  static bool parse(const std::string& s, std::string* v) {
    *v = s;
    return true;
  }
  static bool parse(const std::string& s, double* v) {
    char* end = nullptr;
    *v = std::strtod(s.c_str(), &end);
    return !s.empty() && *end == '\0';
  }
  static bool parse(const std::string& s, int* v) {
    char* end = nullptr;
    const long l = std::strtol(s.c_str(), &end, 10);
    *v = static_cast<int>(l);
    return !s.empty() && *end == '\0' && l == *v;
  }
  static bool parse(const std::string& s, bool* v) {
    if (s == "true" || s == "1")
      *v = true;
    else if (s == "false" || s == "0")
      *v = false;
    else
      return false;
    return true;
  }

  const std::map<std::string, std::string>& values_;
  std::set<std::string> asked_;
  std::string error_;
};

/// Reads from the parameter server.
struct ServerReader {
  const ros::NodeHandle& nh;
  template <class T>
  void operator()(const char* name, T* value) {
    nh.param(name, *value, *value);
  }
};

/// Reads from a dynamic_reconfigure message.
struct MessageReader {
  const dynamic_reconfigure::Config& msg;
  template <class List, class T>
  static void find(const List& list, const char* name, T* value) {
    for (const auto& entry : list)
      if (entry.name == name) *value = static_cast<T>(entry.value);
  }
  void operator()(const char* name, double* value) const { find(msg.doubles, name, value); }
  void operator()(const char* name, int* value) const { find(msg.ints, name, value); }
  void operator()(const char* name, bool* value) const { find(msg.bools, name, value); }
  void operator()(const char* name, std::string* value) const { find(msg.strs, name, value); }
};

/// Writes into a dynamic_reconfigure message the names it is asked for.
struct MessageWriter {
  const std::set<std::string>& names;
  dynamic_reconfigure::Config* msg;
  template <class Entry, class List, class T>
  void add(List* list, const char* name, const T& value) const {
    if (!names.count(name)) return;
    Entry entry;
    entry.name = name;
    entry.value = value;
    list->push_back(entry);
  }
  void operator()(const char* name, double* value) const {
    add<dynamic_reconfigure::DoubleParameter>(&msg->doubles, name, *value);
  }
  void operator()(const char* name, int* value) const {
    add<dynamic_reconfigure::IntParameter>(&msg->ints, name, *value);
  }
  void operator()(const char* name, bool* value) const {
    add<dynamic_reconfigure::BoolParameter>(&msg->bools, name, *value);
  }
  void operator()(const char* name, std::string* value) const {
    add<dynamic_reconfigure::StrParameter>(&msg->strs, name, *value);
  }
};

}  // namespace

void toReconfigureMessage(const DisparityMapperParameters& params, const std::set<std::string>& names,
                          dynamic_reconfigure::Config* msg) {
  DisparityMapperParameters copy = params;  // the reader visits members by reference
  MessageWriter writer{names, msg};
  TableReader<MessageWriter> visit(writer);
  DisparityMapperParameters::forEachParameter(copy, visit);
}

bool fromReconfigureMessage(const dynamic_reconfigure::Config& msg, DisparityMapperParameters* params,
                            std::string* why) {
  DisparityMapperParameters next = *params;
  MessageReader source{msg};
  if (!readParameters(source, &next, why)) return false;
  *params = next;
  return true;
}

bool loadParameters(const ros::NodeHandle& nh, DisparityMapperParameters* p, std::string* why) {
  ServerReader source{nh};
  return readParameters(source, p, why);
}

bool loadParameters(const ros::NodeHandle& nh, OctomapAccumulatorParameters* p, std::string* why) {
  ServerReader source{nh};
  return readParameters(source, p, why);
}

bool loadParameters(const ros::NodeHandle& nh, PathWatcherParameters* p, std::string* why) {
  ServerReader source{nh};
  return readParameters(source, p, why);
}

bool loadParameters(const std::map<std::string, std::string>& values, DisparityMapperParameters* mapper,
                    OctomapAccumulatorParameters* accumulator, std::string* why) {
  PairReader read(values);
  const bool mapper_ok = readParameters(read, mapper, why);
  if (!read.error().empty()) return fail(why, read.error());
  if (!mapper_ok) return false;
  const bool accumulator_ok = readParameters(read, accumulator, why);
  if (!read.error().empty()) return fail(why, read.error());
  if (!accumulator_ok) return false;
  for (const auto& kv : values)
    if (!read.asked().count(kv.first)) return fail(why, "unknown parameter '" + kv.first + "'");
  return true;
}

}  // namespace stereo_occupancy
