#include "stereo_occupancy/ros/parameters.h"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <cstdint>
#include <cstdlib>
#include <set>

namespace stereo_occupancy {

namespace {
bool fail(std::string* why, const std::string& text) {
  if (why) *why = text;
  return false;
}
/// A name that stays inside its directory: no '/', not "." or "..", no hidden file.
bool isPlainFileName(const std::string& name) {
  if (name.empty() || name[0] == '.') return false;
  for (char c : name)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.')) return false;
  return true;
}
}  // namespace

bool DisparityMapperParameters::isValid(std::string* why) const {
  if (world_frame.empty()) return fail(why, "world_frame must not be empty");
  if (!(std::isfinite(tf_timeout_s) && tf_timeout_s >= 0.0 && tf_timeout_s <= 60.0))
    return fail(why, "tf_timeout_s must be in [0, 60]");
  if (queue_size < 1 || queue_size > 100) return fail(why, "queue_size must be in [1, 100]");
  if (!(std::isfinite(depth_baseline_m) && depth_baseline_m > 0.0 && depth_baseline_m <= 10.0))
    return fail(why, "depth_baseline_m must be in (0, 10]");
  if (!std::isfinite(cx_px) || !std::isfinite(cy_px)) return fail(why, "cx_px and cy_px must be finite");
  if (max_image_pixels < 1) return fail(why, "max_image_pixels must be >= 1");
  if (!(std::isfinite(camera.min_range_m) && camera.min_range_m >= 0.05 && camera.min_range_m <= 10.0))
    return fail(why, "min_range_m must be in [0.05, 10]");
  if (!(std::isfinite(camera.max_range_m) && camera.max_range_m > camera.min_range_m &&
        camera.max_range_m <= 200.0))
    return fail(why, "max_range_m must be in (min_range_m, 200]");
  if (!(std::isfinite(camera.delta_d_px) && camera.delta_d_px >= 0.01 && camera.delta_d_px <= 5.0))
    return fail(why, "delta_d_px must be in [0.01, 5]");
  return drawing.isValid(why);
}

bool OctomapAccumulatorParameters::isValid(std::string* why) const {
  if (!(std::isfinite(publish_rate_hz) && publish_rate_hz > 0.0 && publish_rate_hz <= 100.0))
    return fail(why, "publish_rate_hz must be in (0, 100]");
  if (!(std::isfinite(prune_period_s) && prune_period_s > 0.0)) return fail(why, "prune_period_s must be > 0");
  if (!(std::isfinite(save_period_s) && save_period_s >= 0.0)) return fail(why, "save_period_s must be >= 0");
  if (!isPlainFileName(map_name))
    return fail(why, "map_name must be a plain file name: letters, digits, '_', '-', '.', not starting with '.'");
  return map.isValid(why);
}

namespace {

/// Reads every mapper parameter through read(name, value), which leaves
/// value unchanged when the source does not have the name.
template <class Read>
bool readParameters(Read&& read, DisparityMapperParameters* p, std::string* why) {
  read("world_frame", p->world_frame);
  read("tf_timeout_s", p->tf_timeout_s);
  read("queue_size", p->queue_size);
  read("use_depth", p->use_depth);
  read("depth_baseline_m", p->depth_baseline_m);
  read("cx_px", p->cx_px);
  read("cy_px", p->cy_px);
  read("max_image_pixels", p->max_image_pixels);
  read("min_range_m", p->camera.min_range_m);
  read("max_range_m", p->camera.max_range_m);
  read("delta_d_px", p->camera.delta_d_px);
  std::string algorithm = toString(p->drawing.algorithm);
  read("algorithm", algorithm);
  if (!parseDrawingAlgorithm(algorithm, &p->drawing.algorithm))
    return fail(why, "algorithm must be one of " + drawingAlgorithmNames() + " (got '" + algorithm + "')");
  read("resolution_m", p->drawing.resolution_m);
  std::string profile = toString(p->drawing.sensor_model.profile);
  read("sensor_profile", profile);
  if (!parseSensorProfile(profile, &p->drawing.sensor_model.profile))
    return fail(why, "sensor_profile must be gaussian or surface (got '" + profile + "')");
  read("tail_sigmas", p->drawing.sensor_model.tail_sigmas);
  read("p_hit", p->drawing.sensor_model.p_hit);
  read("p_free", p->drawing.sensor_model.p_free);
  read("p_sky", p->drawing.sensor_model.p_sky);
  read("free_gap_sigmas", p->drawing.sensor_model.free_gap_sigmas);
  read("k_m", p->drawing.sensor_model.k_m);
  read("p_min", p->drawing.sensor_model.p_min);
  read("p_max", p->drawing.sensor_model.p_max);
  read("sigma_trans_m", p->drawing.blur.sigma_trans_m);
  read("sigma_angle_rad", p->drawing.blur.sigma_angle_rad);
  read("sigma_step_cells", p->drawing.blur.sigma_step_cells);
  return p->isValid(why);
}

template <class Read>
bool readParameters(Read&& read, OctomapAccumulatorParameters* p, std::string* why) {
  read("world_frame", p->world_frame);
  read("resolution_m", p->map.resolution_m);
  read("clamping_min_prob", p->map.clamping_min_prob);
  read("clamping_max_prob", p->map.clamping_max_prob);
  read("occupancy_threshold_prob", p->map.occupancy_threshold_prob);
  read("max_extent_m", p->map.max_extent_m);
  int max_update_cells = static_cast<int>(std::min<uint64_t>(p->map.max_update_cells, INT32_MAX));
  read("max_update_cells", max_update_cells);
  p->map.max_update_cells = max_update_cells > 0 ? static_cast<uint64_t>(max_update_cells) : 0;
  read("publish_rate_hz", p->publish_rate_hz);
  read("prune_period_s", p->prune_period_s);
  read("save_dir", p->save_dir);
  read("map_name", p->map_name);
  read("save_period_s", p->save_period_s);
  return p->isValid(why);
}

/// Reads from name=value pairs; remembers which names it was asked for and
/// values it could not parse.
class PairReader {
 public:
  explicit PairReader(const std::map<std::string, std::string>& values) : values_(values) {}

  template <class T>
  void operator()(const char* name, T& value) {
    asked_.insert(name);
    const auto it = values_.find(name);
    if (it == values_.end()) return;
    T parsed = value;
    if (parse(it->second, &parsed)) value = parsed;
    else if (error_.empty()) error_ = std::string(name) + ": cannot read '" + it->second + "'";
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
    if (s == "true" || s == "1") *v = true;
    else if (s == "false" || s == "0") *v = false;
    else return false;
    return true;
  }

  const std::map<std::string, std::string>& values_;
  std::set<std::string> asked_;
  std::string error_;
};

}  // namespace

bool loadParameters(const ros::NodeHandle& nh, DisparityMapperParameters* p, std::string* why) {
  return readParameters([&](const char* name, auto& value) { nh.param(name, value, value); }, p, why);
}

bool loadParameters(const ros::NodeHandle& nh, OctomapAccumulatorParameters* p, std::string* why) {
  return readParameters([&](const char* name, auto& value) { nh.param(name, value, value); }, p, why);
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
