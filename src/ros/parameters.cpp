#include "stereo_occupancy/ros/parameters.h"

#include <cmath>

namespace stereo_occupancy {

namespace {
bool fail(std::string* why, const std::string& text) {
  if (why) *why = text;
  return false;
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
  if (map_name.empty() || map_name.find('/') != std::string::npos)
    return fail(why, "map_name must be a file name without '/'");
  return map.isValid(why);
}

bool loadParameters(const ros::NodeHandle& nh, DisparityMapperParameters* p, std::string* why) {
  nh.param("world_frame", p->world_frame, p->world_frame);
  nh.param("tf_timeout_s", p->tf_timeout_s, p->tf_timeout_s);
  nh.param("queue_size", p->queue_size, p->queue_size);
  nh.param("use_depth", p->use_depth, p->use_depth);
  nh.param("depth_baseline_m", p->depth_baseline_m, p->depth_baseline_m);
  nh.param("cx_px", p->cx_px, p->cx_px);
  nh.param("cy_px", p->cy_px, p->cy_px);
  nh.param("max_image_pixels", p->max_image_pixels, p->max_image_pixels);
  nh.param("min_range_m", p->camera.min_range_m, p->camera.min_range_m);
  nh.param("max_range_m", p->camera.max_range_m, p->camera.max_range_m);
  nh.param("delta_d_px", p->camera.delta_d_px, p->camera.delta_d_px);
  std::string algorithm = toString(p->drawing.algorithm);
  nh.param("algorithm", algorithm, algorithm);
  if (!parseDrawingAlgorithm(algorithm, &p->drawing.algorithm))
    return fail(why, "algorithm must be one of line, line_pyramid, raytrace, raytrace_pyramid (got '" + algorithm +
                         "')");
  nh.param("resolution_m", p->drawing.resolution_m, p->drawing.resolution_m);
  nh.param("k_m", p->drawing.sensor_model.k_m, p->drawing.sensor_model.k_m);
  nh.param("p_min", p->drawing.sensor_model.p_min, p->drawing.sensor_model.p_min);
  nh.param("p_max", p->drawing.sensor_model.p_max, p->drawing.sensor_model.p_max);
  nh.param("sigma_trans_m", p->drawing.blur.sigma_trans_m, p->drawing.blur.sigma_trans_m);
  nh.param("sigma_angle_rad", p->drawing.blur.sigma_angle_rad, p->drawing.blur.sigma_angle_rad);
  nh.param("sigma_step_cells", p->drawing.blur.sigma_step_cells, p->drawing.blur.sigma_step_cells);
  return p->isValid(why);
}

bool loadParameters(const ros::NodeHandle& nh, OctomapAccumulatorParameters* p, std::string* why) {
  nh.param("resolution_m", p->map.resolution_m, p->map.resolution_m);
  nh.param("clamping_min_prob", p->map.clamping_min_prob, p->map.clamping_min_prob);
  nh.param("clamping_max_prob", p->map.clamping_max_prob, p->map.clamping_max_prob);
  nh.param("occupancy_threshold_prob", p->map.occupancy_threshold_prob, p->map.occupancy_threshold_prob);
  nh.param("max_extent_m", p->map.max_extent_m, p->map.max_extent_m);
  nh.param("publish_rate_hz", p->publish_rate_hz, p->publish_rate_hz);
  nh.param("prune_period_s", p->prune_period_s, p->prune_period_s);
  nh.param("save_dir", p->save_dir, p->save_dir);
  nh.param("map_name", p->map_name, p->map_name);
  return p->isValid(why);
}

}  // namespace stereo_occupancy
