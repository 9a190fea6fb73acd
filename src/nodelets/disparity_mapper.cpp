// stereo_occupancy/DisparityMapper: disparity image + tf -> occupancy update.
//
// ROS glue only: parameters come from ros/parameters, messages are converted
// in ros/conversions, all drawing is the core's DisparityDrawer.

#include <diagnostic_updater/diagnostic_updater.h>
#include <diagnostic_updater/update_functions.h>
#include <dynamic_reconfigure/server.h>
#include <image_transport/image_transport.h>
#include <image_transport/subscriber_filter.h>
#include <message_filters/subscriber.h>
#include <nodelet/nodelet.h>
#include <ros/ros.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/message_filter.h>
#include <tf2_ros/transform_listener.h>
#include <pluginlib/class_list_macros.hpp>

#include <boost/bind/bind.hpp>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <memory>
#include <mutex>
#include <set>
#include <string>

#include "stereo_occupancy/DisparityMapperConfig.h"
#include "stereo_occupancy/ros/map_conversions.h"
#include "stereo_occupancy/ros/mapping_pipeline.h"
#include "stereo_occupancy/ros/parameters.h"
#include "stereo_occupancy/ros/processing_times.h"

namespace stereo_occupancy {

namespace {

/// Image stamps farther than this from the clock are not taken as a jump of
/// the time line (a looping bag moves the clock with its stamps) [s].
constexpr double kStampClockToleranceS = 10.0;

/// Images arriving without one mapped for this long: look for world_frame in tf [s].
constexpr double kNoProgressWarnS = 5.0;

/// At most one warning of a kind in this time [s].
constexpr double kWarnThrottleS = 5.0;
/// The world-frame warning repeats less often: it names every frame in tf [s].
constexpr double kWorldFrameWarnThrottleS = 10.0;

/// The values in use, as the dynamic_reconfigure server shows them.
void toConfig(const DisparityMapperParameters& p, DisparityMapperConfig* config) {
  std::set<std::string> names;  // those of the .cfg
  for (const auto& description : DisparityMapperConfig::__getParamDescriptions__()) names.insert(description->name);
  dynamic_reconfigure::Config msg;
  toReconfigureMessage(p, names, &msg);
  config->__fromMessage__(msg);
}

}  // namespace

class DisparityMapper : public nodelet::Nodelet {
 public:
  ~DisparityMapper() override;

 private:
  void onInit() override;

  void disparityCallback(const stereo_msgs::DisparityImageConstPtr& msg);
  void depthCallback(const sensor_msgs::ImageConstPtr& msg);
  void cameraInfoCallback(const sensor_msgs::CameraInfoConstPtr& msg);
  template <class M>
  void transformFailure(const boost::shared_ptr<const M>& msg, tf2_ros::FilterFailureReason reason);
  void reconfigure(DisparityMapperConfig& config, uint32_t level);
  void diagnose(diagnostic_updater::DiagnosticStatusWrapper& status);

  /// Every image as it arrives, before it waits for its pose: notices time
  /// going backwards (a looping bag) and clears the poses of the old time line.
  template <class M>
  void arrival(const boost::shared_ptr<const M>& msg);
  /// Images come but none has been mapped for a while: says whether
  /// world_frame exists in tf at all (a typo, a missing localisation node).
  void checkWorldFrame();
  /// Runs one image that has its pose through the pipeline (@p map_image
  /// calls FrameMapping::map or mapDepth), then publishes and logs.
  template <class MapImage>
  void process(const char* what, MapImage&& map_image);

  /// A copy of the parameters in use (dynamic_reconfigure changes them under mutex_).
  DisparityMapperParameters parameters() const {
    std::lock_guard<std::mutex> lock(mutex_);
    return mapping_->parameters();
  }

  // Everything below is guarded by mutex_: a nodelet's callbacks may run on
  // several threads of the manager's pool at once.
  mutable std::mutex mutex_;
  std::unique_ptr<FrameMapping> mapping_;  ///< the pipeline: checks, draw, update
  sensor_msgs::CameraInfoConstPtr camera_info_;
  uint64_t filter_dropped_ = 0;  ///< images the tf filter dropped (no pose in time); the pipeline counts the rest
  ProcessingTimes processing_times_{/*cpu_time=*/true};  ///< per image: draw, blur, encode, publish
  std::string last_problem_;
  ros::Time last_image_stamp_;
  uint64_t time_jumps_back_ = 0;
  uint64_t images_arrived_ = 0;  ///< before the tf filter (FrameCounters::images counts those with a pose)
  uint64_t processed_at_last_check_ = 0, arrived_at_last_check_ = 0;
  ros::WallTime last_progress_ = ros::WallTime::now();  ///< when an image was last mapped (checkWorldFrame)

  std::unique_ptr<tf2_ros::Buffer> tf_buffer_;
  std::unique_ptr<tf2_ros::TransformListener> tf_listener_;
  message_filters::Subscriber<stereo_msgs::DisparityImage> disparity_sub_;
  std::unique_ptr<tf2_ros::MessageFilter<stereo_msgs::DisparityImage>> disparity_filter_;
  std::unique_ptr<image_transport::ImageTransport> image_transport_;
  image_transport::SubscriberFilter depth_sub_;
  std::unique_ptr<tf2_ros::MessageFilter<sensor_msgs::Image>> depth_filter_;
  ros::Subscriber camera_info_sub_;
  ros::Publisher update_pub_;
  ros::Publisher cloud_pub_;
  ros::Publisher disparity_image_pub_;  ///< the input's image, for rviz, only while watched

  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<DisparityMapperConfig>> reconfigure_server_;
  std::unique_ptr<diagnostic_updater::Updater> diagnostics_;
  double min_rate_hz_ = 1.0, max_rate_hz_ = 100.0;
  std::unique_ptr<diagnostic_updater::FrequencyStatus> input_rate_;
  ros::Timer diagnostics_timer_;
};

void DisparityMapper::onInit() {
  using boost::placeholders::_1;
  using boost::placeholders::_2;
  ros::NodeHandle& nh = getNodeHandle();
  ros::NodeHandle& pnh = getPrivateNodeHandle();

  DisparityMapperParameters params;
  std::string why;
  if (!loadParameters(pnh, &params, &why)) {
    // Refuse to start: no subscription, no output. The manager and its other
    // nodelets keep running.
    NODELET_FATAL("%s: invalid parameter: %s; DisparityMapper does not start", getName().c_str(), why.c_str());
    return;
  }
  mapping_ = std::make_unique<FrameMapping>(params);

  tf_buffer_ = std::make_unique<tf2_ros::Buffer>();
  tf_listener_ = std::make_unique<tf2_ros::TransformListener>(*tf_buffer_, nh);

  update_pub_ = nh.advertise<OccupancyUpdate>("occupancy_update", 5);
  cloud_pub_ = nh.advertise<sensor_msgs::PointCloud2>("local_grid_cloud", 1);
  disparity_image_pub_ = nh.advertise<sensor_msgs::Image>("disparity_image", 1);

  if (params.use_depth) {
    image_transport_ = std::make_unique<image_transport::ImageTransport>(nh);
    depth_sub_.subscribe(*image_transport_, "depth", params.queue_size);
    depth_filter_ = std::make_unique<tf2_ros::MessageFilter<sensor_msgs::Image>>(
        depth_sub_, *tf_buffer_, params.world_frame, params.queue_size, nh);
    depth_filter_->registerCallback(boost::bind(&DisparityMapper::depthCallback, this, _1));
    depth_sub_.registerCallback(boost::bind(&DisparityMapper::arrival<sensor_msgs::Image>, this, _1));
    depth_filter_->registerFailureCallback(
        boost::bind(&DisparityMapper::transformFailure<sensor_msgs::Image>, this, _1, _2));
    camera_info_sub_ = nh.subscribe("camera_info", 1, &DisparityMapper::cameraInfoCallback, this);
  } else {
    disparity_sub_.subscribe(nh, "disparity", params.queue_size);
    disparity_filter_ = std::make_unique<tf2_ros::MessageFilter<stereo_msgs::DisparityImage>>(
        disparity_sub_, *tf_buffer_, params.world_frame, params.queue_size, nh);
    disparity_filter_->registerCallback(boost::bind(&DisparityMapper::disparityCallback, this, _1));
    disparity_sub_.registerCallback(boost::bind(&DisparityMapper::arrival<stereo_msgs::DisparityImage>, this, _1));
    disparity_filter_->registerFailureCallback(
        boost::bind(&DisparityMapper::transformFailure<stereo_msgs::DisparityImage>, this, _1, _2));
    // Optional: the principal point of the rectified left camera.
    camera_info_sub_ = nh.subscribe("camera_info", 1, &DisparityMapper::cameraInfoCallback, this);
  }

  reconfigure_server_ = std::make_unique<dynamic_reconfigure::Server<DisparityMapperConfig>>(reconfigure_mutex_, pnh);
  DisparityMapperConfig initial;
  toConfig(params, &initial);
  {
    boost::recursive_mutex::scoped_lock lock(reconfigure_mutex_);
    reconfigure_server_->updateConfig(initial);
  }
  reconfigure_server_->setCallback(boost::bind(&DisparityMapper::reconfigure, this, _1, _2));

  diagnostics_ = std::make_unique<diagnostic_updater::Updater>(nh, pnh, getName());
  diagnostics_->setHardwareID("stereo_occupancy");
  input_rate_ = std::make_unique<diagnostic_updater::FrequencyStatus>(
      diagnostic_updater::FrequencyStatusParam(&min_rate_hz_, &max_rate_hz_, 0.1, 10));
  diagnostics_->add(*input_rate_);
  diagnostics_->add("mapper", this, &DisparityMapper::diagnose);
  diagnostics_timer_ = nh.createTimer(ros::Duration(1.0), [this](const ros::TimerEvent&) {
    checkWorldFrame();
    diagnostics_->update();
  });

  NODELET_INFO("DisparityMapper: %s with the %s profile at %.3g m cells into frame '%s', range %.3g m, from '%s'",
               toString(params.drawing.algorithm), toString(params.drawing.sensor_model.profile),
               params.drawing.resolution_m, params.world_frame.c_str(), params.camera.max_range_m,
               params.use_depth ? nh.resolveName("depth").c_str() : nh.resolveName("disparity").c_str());
}

DisparityMapper::~DisparityMapper() {
  std::lock_guard<std::mutex> lock(mutex_);
  if (processing_times_.empty()) return;
  const TimeStatistics wall = processing_times_.statistics();
  const TimeStatistics cpu = processing_times_.cpuStatistics();
  const FrameCounters& n = mapping_->counters();
  const DisparityMapperParameters& params = mapping_->parameters();
  // One line for scripts: counts and the processing time per image (draw,
  // blur, encode, publish). On stderr: rosconsole may be gone at shutdown.
  std::fprintf(stderr,
               "DisparityMapper summary: images_received=%lu images_processed=%lu dropped_no_transform=%lu "
               "dropped_invalid=%lu ms_per_image_mean=%.3f ms_per_image_median=%.3f ms_per_image_p99=%.3f "
               "ms_per_image_max=%.3f cpu_ms_per_image_median=%.3f cpu_ms_per_image_p99=%.3f algorithm=%s "
               "resolution_m=%.2f\n",
               static_cast<unsigned long>(n.images), static_cast<unsigned long>(n.mapped),
               static_cast<unsigned long>(n.no_transform + filter_dropped_), static_cast<unsigned long>(n.refused),
               wall.mean_ms, wall.median_ms, wall.p99_ms, wall.max_ms, cpu.median_ms, cpu.p99_ms,
               toString(params.drawing.algorithm), params.drawing.resolution_m);
}

void DisparityMapper::reconfigure(DisparityMapperConfig& config, uint32_t /*level*/) {
  // The server clamps each value to its range in the .cfg (the table's);
  // cross-checks (min_range_m < max_range_m, ...) and the choices' names are
  // the table's too. A refused request leaves the values in use, and the
  // server shows those.
  std::lock_guard<std::mutex> lock(mutex_);
  DisparityMapperParameters next = mapping_->parameters();
  dynamic_reconfigure::Config msg;
  config.__toMessage__(msg);
  std::string why;
  if (!fromReconfigureMessage(msg, &next, &why)) {
    NODELET_WARN("dynamic_reconfigure: %s; keeping the previous values", why.c_str());
    toConfig(mapping_->parameters(), &config);
    return;
  }
  mapping_->setParameters(next);
}

void DisparityMapper::cameraInfoCallback(const sensor_msgs::CameraInfoConstPtr& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  camera_info_ = msg;
}

template <class M>
void DisparityMapper::transformFailure(const boost::shared_ptr<const M>& msg, tf2_ros::FilterFailureReason reason) {
  const char* what = reason == tf2_ros::filter_failure_reasons::OutTheBack     ? "older than the tf cache"
                     : reason == tf2_ros::filter_failure_reasons::EmptyFrameID ? "empty frame_id"
                                                                               : "no transform in time";
  {
    std::lock_guard<std::mutex> lock(mutex_);
    ++filter_dropped_;
    last_problem_ = std::string("dropped an image: ") + what;
  }
  NODELET_WARN_THROTTLE(kWarnThrottleS, "dropped an image from '%s' at %.3f: %s (to '%s')",
                        msg->header.frame_id.c_str(), msg->header.stamp.toSec(), what,
                        parameters().world_frame.c_str());
}

template <class M>
void DisparityMapper::arrival(const boost::shared_ptr<const M>& msg) {
  std::lock_guard<std::mutex> lock(mutex_);
  ++images_arrived_;
  // Only stamps near the clock speak for the time line: one image stamped 0
  // (or a year ahead) must not clear the poses of every other image.
  const ros::Time stamp = msg->header.stamp;
  if (std::abs((stamp - ros::Time::now()).toSec()) > kStampClockToleranceS) return;
  // A looping bag or a restarted source: stamps jump back. The poses in the
  // tf buffer belong to the old time line (and tf2 refuses "old" data while
  // they are there); start over.
  if (!last_image_stamp_.isZero() && stamp + ros::Duration(1.0) < last_image_stamp_) {
    ++time_jumps_back_;
    last_problem_ = "image stamps went back";
    NODELET_WARN(
        "image stamps went back by %.3f s (a looping bag?): clearing the tf buffer; the accumulated map "
        "keeps what it has (call the accumulator's ~reset to start over)",
        (last_image_stamp_ - msg->header.stamp).toSec());
    tf_buffer_->clear();
  }
  last_image_stamp_ = stamp;
}

void DisparityMapper::checkWorldFrame() {
  const DisparityMapperParameters params = parameters();
  uint64_t arrived, processed;
  {
    std::lock_guard<std::mutex> lock(mutex_);
    arrived = images_arrived_;
    processed = mapping_->counters().mapped;
    // The clock starts with the first image, and again with each one mapped.
    if (processed != processed_at_last_check_ || (arrived > 0 && arrived_at_last_check_ == 0))
      last_progress_ = ros::WallTime::now();
    processed_at_last_check_ = processed;
    arrived_at_last_check_ = arrived;
  }
  if (arrived == 0 || (ros::WallTime::now() - last_progress_).toSec() < kNoProgressWarnS) return;
  if (tf_buffer_->_frameExists(params.world_frame)) return;
  std::string frames = tf_buffer_->allFramesAsString();
  std::replace(frames.begin(), frames.end(), '\n', ' ');
  {
    std::lock_guard<std::mutex> lock(mutex_);
    last_problem_ = "world_frame '" + params.world_frame + "' does not exist in tf";
  }
  NODELET_WARN_THROTTLE(kWorldFrameWarnThrottleS,
                        "%lu images came but none was mapped for %.0f s: world_frame '%s' does not exist in tf "
                        "(%s)",
                        static_cast<unsigned long>(arrived), kNoProgressWarnS, params.world_frame.c_str(),
                        frames.empty() ? "tf holds no frames" : frames.c_str());
}

void DisparityMapper::disparityCallback(const stereo_msgs::DisparityImageConstPtr& msg) {
  process("disparity image", [&](const sensor_msgs::CameraInfoConstPtr& info, FrameResult* result) {
    return mapping_->map(msg, info, *tf_buffer_, ros::Time::now(), result);
  });
  if (disparity_image_pub_.getNumSubscribers() > 0)
    disparity_image_pub_.publish(boost::make_shared<sensor_msgs::Image>(msg->image));  // a copy, only for viewers
}

void DisparityMapper::depthCallback(const sensor_msgs::ImageConstPtr& msg) {
  process("depth image", [&](const sensor_msgs::CameraInfoConstPtr& info, FrameResult* result) {
    return mapping_->mapDepth(msg, info, *tf_buffer_, ros::Time::now(), result);
  });
}

template <class MapImage>
void DisparityMapper::process(const char* what, MapImage&& map_image) {
  input_rate_->tick();
  std::lock_guard<std::mutex> lock(mutex_);
  const ProcessingTimes::Start start = processing_times_.start();
  FrameResult result;
  const OccupancyUpdatePtr update = map_image(camera_info_, &result);  // catches what it throws
  if (!update) {
    last_problem_ = result.why;
    if (result.setup_refused_now)
      NODELET_ERROR(
          "cannot map with this camera and these parameters: %s; its images are dropped until the "
          "camera or the parameters (dynamic_reconfigure) change",
          result.why.c_str());
    else if (result.outcome == FrameOutcome::kNoTransform)
      NODELET_WARN_THROTTLE(kWarnThrottleS, "dropped a %s: %s", what, result.why.c_str());
    else if (result.why != mapping_->refusedSetup())  // a refused set-up was reported once, as an error
      NODELET_WARN_THROTTLE(kWarnThrottleS, "refused a %s: %s", what, result.why.c_str());
    return;
  }
  if (!result.info_mismatch.empty()) {
    last_problem_ = result.info_mismatch;
    NODELET_WARN_THROTTLE(kWarnThrottleS, "%s (%lu such images so far)", result.info_mismatch.c_str(),
                          static_cast<unsigned long>(mapping_->counters().info_mismatch));
  }
  if (result.mapped_nothing) {
    last_problem_ = result.why;
    NODELET_WARN_THROTTLE(kWarnThrottleS, "%s (%lu such images so far)", result.why.c_str(),
                          static_cast<unsigned long>(mapping_->counters().mapped_nothing));
  }
  update->source = getName();   // nodelets in one manager share a node name
  update_pub_.publish(update);  // as Ptr: no copy to nodelets in the same manager
  if (cloud_pub_.getNumSubscribers() > 0) {
    try {  // bad_alloc for a huge grid: nothing may leave a callback, and the update is out already
      auto cloud = boost::make_shared<sensor_msgs::PointCloud2>();
      occupiedCellCloud(mapping_->grid(), update->header, cloud.get());
      cloud_pub_.publish(cloud);
    } catch (const std::exception& e) {
      NODELET_WARN_THROTTLE(kWarnThrottleS, "no local_grid_cloud for this image: %s", e.what());
    }
  }
  processing_times_.stop(start);
}

void DisparityMapper::diagnose(diagnostic_updater::DiagnosticStatusWrapper& status) {
  std::lock_guard<std::mutex> lock(mutex_);
  const FrameCounters& n = mapping_->counters();
  const bool dropping = n.no_transform + filter_dropped_ + n.refused + n.mapped_nothing + n.info_mismatch > 0;
  if (!mapping_->refusedSetup().empty())
    status.summary(diagnostic_msgs::DiagnosticStatus::ERROR,
                   "cannot map with this camera: " + mapping_->refusedSetup());
  else
    status.summary(dropping ? diagnostic_msgs::DiagnosticStatus::WARN : diagnostic_msgs::DiagnosticStatus::OK,
                   dropping ? last_problem_ : "mapping");
  status.add("algorithm", toString(mapping_->parameters().drawing.algorithm));
  status.add("images arrived", images_arrived_);
  status.add("images received", n.images);
  status.add("images processed", n.mapped);
  status.add("dropped: no transform", n.no_transform + filter_dropped_);
  status.add("dropped: invalid input", n.refused);
  status.add("mapped nothing", n.mapped_nothing);
  status.add("camera_info not used", n.info_mismatch);
  status.add("time jumps back", time_jumps_back_);
  status.add("last processing time [ms]", processing_times_.lastMs());
  status.add("max processing time [ms]", processing_times_.maxMs());
  // Since the last report (1 s): what a soak plots over time.
  const TimeStatistics window = processing_times_.takeWindow();
  status.add("processing time p50 since last report [ms]", window.median_ms);
  status.add("processing time p99 since last report [ms]", window.p99_ms);
}

}  // namespace stereo_occupancy

PLUGINLIB_EXPORT_CLASS(stereo_occupancy::DisparityMapper, nodelet::Nodelet)
