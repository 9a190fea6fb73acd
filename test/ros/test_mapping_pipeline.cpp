// The mapping pipeline that the nodelets and bag_to_map share, with a real
// tf2::BufferCore (no roscore needed).

#include <gtest/gtest.h>

#include <tf2/buffer_core.h>

#include <boost/make_shared.hpp>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <set>
#include <string>
#include <utility>
#include <vector>

#include "stereo_occupancy/ros/input_conversions.h"
#include "stereo_occupancy/ros/map_conversions.h"
#include "stereo_occupancy/ros/mapping_pipeline.h"
#include "stereo_occupancy/ros/parameters.h"
#include "stereo_occupancy/sim/synthetic_scene.h"
#include "stereo_occupancy/stage_times.h"

using namespace stereo_occupancy;

namespace {

/// A wall 12 m ahead of a camera 2 m up, looking along the world's x axis.
class PipelineTest : public ::testing::Test {
 protected:
  void SetUp() override {
    T_W_C_.setIdentity();
    T_W_C_.linear() << 0, 0, 1, -1, 0, 0, 0, -1, 0;  // optical z along world x, y down
    T_W_C_.translation() = Eigen::Vector3d(0.0, 0.0, 2.0);
    SyntheticScene scene;
    scene.addBox(Eigen::Vector3d(12.0, -3.0, 0.0), Eigen::Vector3d(13.0, 3.0, 4.0));
    image_ = renderDisparity(scene, StereoCameraModel(StereoCameraConfig()), T_W_C_);
  }

  /// The image at @p stamp, and its pose in tf.
  stereo_msgs::DisparityImageConstPtr frame(double stamp_s, bool with_pose = true) {
    const ros::Time stamp(stamp_s);
    if (with_pose) tf_.setTransform(toTransformMsg(T_W_C_, stamp, "map", "camera_optical"), "test");
    std_msgs::Header header;
    header.stamp = stamp;
    header.frame_id = "camera_optical";
    auto msg = boost::make_shared<stereo_msgs::DisparityImage>();
    toDisparityImageMsg(image_, header, StereoCameraConfig(), 128.0, 1.0 / 16.0, msg.get());
    return msg;
  }

  tf2::BufferCore tf_{ros::Duration(100.0)};
  Eigen::Isometry3d T_W_C_;
  cv::Mat image_;
};

}  // namespace

TEST_F(PipelineTest, AnImageWithItsPoseBecomesAnUpdateTheMapFuses) {
  FrameMapping mapping{DisparityMapperParameters()};
  FrameResult result;
  const OccupancyUpdatePtr update = mapping.map(frame(10.0), nullptr, tf_, ros::Time(10.001), &result);
  ASSERT_TRUE(update) << result.why;
  EXPECT_EQ(result.outcome, FrameOutcome::kMapped);
  EXPECT_EQ(update->header.frame_id, "map");  // the world frame, not the camera's
  EXPECT_EQ(update->header.stamp, ros::Time(10.0));
  EXPECT_NEAR(update->sensor_origin.z, 2.0, 1e-9);
  EXPECT_GT(update->log_odds.size(), 10000u);
  GridUpdateView view;
  std::string why;
  ASSERT_TRUE(viewOf(*update, &view, &why) && view.isConsistent(&why)) << why;
  size_t wall_occupied = 0;
  view.forEachCell([&](const Eigen::Vector3i& g, float v) { wall_occupied += g.x() == 48 && v > 0.0f; });
  EXPECT_GT(wall_occupied, 100u);  // the wall's face, x in [12, 12.25) m

  MapFusion fusion{OctomapAccumulatorParameters()};
  ASSERT_TRUE(fusion.fuse(*update, &why)) << why;
  EXPECT_EQ(fusion.map().updates(), 1u);
  EXPECT_EQ(fusion.frameId(), "map");
  EXPECT_EQ(fusion.lastStamp(), ros::Time(10.0));
  const octomap::OcTreeNode* wall = fusion.map().tree().search(12.1, 0.1, 2.1);
  ASSERT_NE(wall, nullptr);
  EXPECT_GT(wall->getLogOdds(), 0.0f);
  EXPECT_EQ(mapping.counters().mapped, 1u);
  EXPECT_EQ(mapping.counters().images, 1u);
}

// The stage timing (performance --stages) accounts for the whole path, adds
// up over frames, stops when taken away, and changes nothing in the update.
TEST_F(PipelineTest, StageTimesAccountForThePathAndChangeNothing) {
  DisparityMapperParameters params;
  params.drawing.blur.sigma_trans_m = 0.1;  // a blur to time
  FrameMapping timed{params}, untimed{params};
  MapFusion fusion{OctomapAccumulatorParameters()};
  StageTimes times;
  timed.setStageTimes(&times);
  fusion.setStageTimes(&times);
  FrameResult result;
  std::string why;
  const auto t0 = std::chrono::steady_clock::now();
  const OccupancyUpdatePtr update = timed.map(frame(10.0), nullptr, tf_, ros::Time(10.0), &result);
  ASSERT_TRUE(update) << result.why;
  ASSERT_TRUE(fusion.fuse(*update, &why)) << why;
  const double wall_ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
  for (PathStage stage :
       {PathStage::kInput, PathStage::kGridPreparation, PathStage::kPyramids, PathStage::kDrawing, PathStage::kGuards,
        PathStage::kBlur, PathStage::kEncoding, PathStage::kMessage, PathStage::kFusion})
    EXPECT_GT(times[stage], 0.0) << toString(stage);
  EXPECT_EQ(times[PathStage::kMaintenance], 0.0);  // not due after one update
  EXPECT_LE(times.total(), wall_ms);
  EXPECT_GT(times[PathStage::kDrawing], times[PathStage::kMessage]);

  const OccupancyUpdatePtr same = untimed.map(frame(10.0), nullptr, tf_, ros::Time(10.0), &result);
  ASSERT_TRUE(same);
  EXPECT_EQ(same->log_odds, update->log_odds);
  EXPECT_EQ(same->run_start, update->run_start);

  const StageTimes after_one = times;
  ASSERT_TRUE(timed.map(frame(11.0), nullptr, tf_, ros::Time(11.0), &result));
  EXPECT_GT(times[PathStage::kDrawing], after_one[PathStage::kDrawing]);  // summed over frames
  EXPECT_EQ(times[PathStage::kFusion], after_one[PathStage::kFusion]);    // not fused
  EXPECT_FALSE(timed.map(frame(12.0, /*with_pose=*/false), nullptr, tf_, ros::Time(12.0), &result));
  const StageTimes refused = times;
  timed.setStageTimes(nullptr);
  ASSERT_TRUE(timed.map(frame(13.0), nullptr, tf_, ros::Time(13.0), &result));
  EXPECT_EQ(times.ms, refused.ms);  // no longer timed
}

TEST_F(PipelineTest, PosesLateOrMissingAndStampZeroAreNotMapped) {
  FrameMapping mapping{DisparityMapperParameters()};  // tf_timeout_s = 1
  FrameResult result;
  EXPECT_FALSE(mapping.map(frame(10.0), nullptr, tf_, ros::Time(11.5), &result));  // pose known 1.5 s late
  EXPECT_EQ(result.outcome, FrameOutcome::kNoTransform);
  EXPECT_NE(result.why.find("tf_timeout_s"), std::string::npos) << result.why;
  EXPECT_FALSE(mapping.map(frame(20.0, /*with_pose=*/false), nullptr, tf_, ros::Time(20.0), &result));
  EXPECT_EQ(result.outcome, FrameOutcome::kNoTransform);
  auto unstamped = boost::make_shared<stereo_msgs::DisparityImage>(*frame(30.0));
  unstamped->header.stamp = ros::Time();
  EXPECT_FALSE(mapping.map(unstamped, nullptr, tf_, ros::Time(30.0), &result));
  EXPECT_EQ(result.outcome, FrameOutcome::kRefused);
  EXPECT_EQ(mapping.counters().images, 3u);
  EXPECT_EQ(mapping.counters().no_transform, 2u);
  EXPECT_EQ(mapping.counters().refused, 1u);
  EXPECT_EQ(mapping.counters().mapped, 0u);
}

// Disparities outside the message's [min_disparity, max_disparity] (as when
// the two cameras' principal points differ) map nothing: said, with the
// counts, and counted.
TEST_F(PipelineTest, AnImageThatMapsNothingSaysWhy) {
  FrameMapping mapping{DisparityMapperParameters()};
  // A matcher's image: no sky, every pixel 12 m away (17.5 px), but a message claiming [0, 5] px.
  auto narrow = boost::make_shared<stereo_msgs::DisparityImage>(*frame(10.0));
  toDisparityImageMsg(cv::Mat(480, 640, CV_32FC1, cv::Scalar(17.5f)), narrow->header, StereoCameraConfig(), 5.0,
                      1.0 / 16.0, narrow.get());
  FrameResult result;
  const OccupancyUpdatePtr update = mapping.map(narrow, nullptr, tf_, ros::Time(10.0), &result);
  ASSERT_TRUE(update) << result.why;
  EXPECT_TRUE(update->log_odds.empty());
  EXPECT_TRUE(result.mapped_nothing);
  EXPECT_NE(result.why.find("outside the valid disparities [0, 5] px"), std::string::npos) << result.why;
  EXPECT_EQ(mapping.counters().mapped_nothing, 1u);
  FrameResult good;
  ASSERT_TRUE(mapping.map(frame(11.0), nullptr, tf_, ros::Time(11.0), &good));
  EXPECT_FALSE(good.mapped_nothing);
  EXPECT_EQ(mapping.counters().mapped_nothing, 1u);
}

// A camera_info that disagrees with the disparity image (another size, no
// rectified projection) cannot give the principal point: the image is mapped
// with the image's centre, and that is said and counted, not silent.
TEST_F(PipelineTest, ACameraInfoThatDisagreesIsSaidAndCounted) {
  FrameMapping mapping{DisparityMapperParameters()};
  auto info = boost::make_shared<sensor_msgs::CameraInfo>();
  info->width = 640;
  info->height = 480;
  info->P[0] = info->P[5] = 700.0;
  info->P[2] = 300.0;  // not the centre: used when it fits
  info->P[6] = 250.0;
  FrameResult result;
  ASSERT_TRUE(mapping.map(frame(10.0), info, tf_, ros::Time(10.0), &result)) << result.why;
  EXPECT_EQ(result.info_mismatch, "");
  auto full_size = boost::make_shared<sensor_msgs::CameraInfo>(*info);  // the raw camera's, 2 x 2 binned images
  full_size->width = 1280;
  full_size->height = 960;
  ASSERT_TRUE(mapping.map(frame(11.0), full_size, tf_, ros::Time(11.0), &result)) << result.why;
  EXPECT_NE(result.info_mismatch.find("camera_info is 1280 x 960 px, the disparity image 640 x 480"), std::string::npos)
      << result.info_mismatch;
  EXPECT_NE(result.info_mismatch.find("(319.500000, 239.500000) px is"), std::string::npos) << result.info_mismatch;
  auto unrectified = boost::make_shared<sensor_msgs::CameraInfo>(*info);
  unrectified->P[0] = 0.0;
  ASSERT_TRUE(mapping.map(frame(12.0), unrectified, tf_, ros::Time(12.0), &result)) << result.why;
  EXPECT_NE(result.info_mismatch.find("no rectified projection"), std::string::npos) << result.info_mismatch;
  ASSERT_TRUE(mapping.map(frame(13.0), nullptr, tf_, ros::Time(13.0), &result)) << result.why;
  EXPECT_EQ(result.info_mismatch, "");  // none given: the parameters' or the centre, as documented
  EXPECT_EQ(mapping.counters().info_mismatch, 2u);
  EXPECT_EQ(mapping.counters().mapped, 4u);
}

// A camera the drawer refuses is tried once and reported once; its images
// are refused with the same reason until the parameters change.
TEST_F(PipelineTest, ARefusedCameraSetUpIsReportedOnce) {
  FrameMapping mapping{DisparityMapperParameters()};
  auto too_fine = [&](double stamp_s) {  // f = 1 px: 0.25 m cells would need lines finer than 2^-10 px
    auto msg = boost::make_shared<stereo_msgs::DisparityImage>(*frame(stamp_s));
    msg->f = 1.0f;
    return stereo_msgs::DisparityImageConstPtr(msg);
  };
  FrameResult first, second;
  EXPECT_FALSE(mapping.map(too_fine(10.0), nullptr, tf_, ros::Time(10.0), &first));
  EXPECT_TRUE(first.setup_refused_now);
  EXPECT_FALSE(mapping.refusedSetup().empty());
  EXPECT_FALSE(mapping.map(too_fine(11.0), nullptr, tf_, ros::Time(11.0), &second));
  EXPECT_FALSE(second.setup_refused_now);
  EXPECT_EQ(second.why, first.why);
  EXPECT_EQ(mapping.counters().refused, 2u);
  mapping.setParameters(mapping.parameters());  // dynamic_reconfigure: try again
  EXPECT_TRUE(mapping.refusedSetup().empty());
  FrameResult good;
  EXPECT_TRUE(mapping.map(frame(12.0), nullptr, tf_, ros::Time(12.0), &good)) << good.why;
}

TEST_F(PipelineTest, TheMapRefusesUpdatesOfAnotherFrameAndChoosesTheFirstWhenAskedTo) {
  FrameMapping mapping{DisparityMapperParameters()};
  FrameResult result;
  const OccupancyUpdatePtr update = mapping.map(frame(10.0), nullptr, tf_, ros::Time(10.0), &result);
  ASSERT_TRUE(update) << result.why;
  OccupancyUpdate odom = *update;
  odom.header.frame_id = "odom";
  MapFusion fusion{OctomapAccumulatorParameters()};
  std::string why;
  EXPECT_FALSE(fusion.fuse(odom, &why));
  EXPECT_NE(why.find("'odom'"), std::string::npos) << why;
  EXPECT_EQ(fusion.map().updates(), 0u);
  EXPECT_EQ(fusion.counters().refused, 1u);

  OctomapAccumulatorParameters any_frame;
  any_frame.world_frame = "";
  MapFusion first_frame{any_frame};
  EXPECT_EQ(first_frame.frameId(), "");
  ASSERT_TRUE(first_frame.fuse(odom, &why)) << why;
  EXPECT_EQ(first_frame.frameId(), "odom");
  EXPECT_FALSE(first_frame.fuse(*update, &why));  // "map" now differs from the map's frame
}

// The mapper numbers its updates; the map counts what never arrived, per
// publisher, and takes a restarted mapper's new count as no loss.
TEST_F(PipelineTest, UpdatesThatNeverArriveAreCounted) {
  FrameMapping mapping{DisparityMapperParameters()};
  std::vector<OccupancyUpdatePtr> updates;
  FrameResult result;
  for (double t : {10.0, 10.1, 10.2, 10.3, 10.4}) {
    updates.push_back(mapping.map(frame(t), nullptr, tf_, ros::Time(t), &result));
    ASSERT_TRUE(updates.back()) << result.why;
    EXPECT_EQ(updates.back()->sequence, updates.size());
  }
  MapFusion fusion{OctomapAccumulatorParameters()};
  std::string why;
  ASSERT_TRUE(fusion.fuse(*updates[0], &why, "/mapper_a"));
  ASSERT_TRUE(fusion.fuse(*updates[3], &why, "/mapper_a"));  // 2 and 3 lost
  EXPECT_EQ(fusion.counters().lost, 2u);
  ASSERT_TRUE(fusion.fuse(*updates[1], &why, "/mapper_b"));  // another publisher: its own count
  ASSERT_TRUE(fusion.fuse(*updates[2], &why, "/mapper_b"));
  EXPECT_EQ(fusion.counters().lost, 2u);
  // Two mappers in one manager: one publisher name, two sources, two counts.
  OccupancyUpdate forward = *updates[1], down = *updates[0];
  forward.source = "/forward_mapper";
  down.source = "/down_mapper";
  ASSERT_TRUE(fusion.fuse(forward, &why, "/manager"));
  ASSERT_TRUE(fusion.fuse(down, &why, "/manager"));
  forward.sequence = 3;
  down.sequence = 2;
  ASSERT_TRUE(fusion.fuse(forward, &why, "/manager"));
  ASSERT_TRUE(fusion.fuse(down, &why, "/manager"));
  EXPECT_EQ(fusion.counters().lost, 2u);
  ASSERT_TRUE(fusion.fuse(*updates[0], &why, "/mapper_a"));  // restarted: counts from 1 again
  ASSERT_TRUE(fusion.fuse(*updates[1], &why, "/mapper_a"));
  EXPECT_EQ(fusion.counters().lost, 2u);
  OccupancyUpdate uncounted = *updates[4];
  uncounted.sequence = 0;  // another node's update without a count
  ASSERT_TRUE(fusion.fuse(uncounted, &why, "/other"));
  EXPECT_EQ(fusion.counters().lost, 2u);
}

// compress_map's merges come after the maintain, over the next updates
// (here MissionMap::kMergeSteps: 22 updates before it), not in the update that maintains: the
// map then has fewer leaves than one that never merges, and every cell its value.
TEST_F(PipelineTest, TheMergesAreSpreadOverTheNextUpdates) {
  OctomapAccumulatorParameters params;
  params.prune_period_s = 5.0;  // one maintain in this test
  OctomapAccumulatorParameters plain_params = params;
  plain_params.map.compress_map = false;
  FrameMapping mapping{DisparityMapperParameters()};
  MapFusion fusion{params}, plain{plain_params};
  std::string why;
  FrameResult result;
  const int maintaining = 21;  // the first update more than 5 s after the first
  for (int k = 0; k <= maintaining + static_cast<int>(MissionMap::kMergeSteps); ++k) {
    const double t = 10.0 + 0.25 * k;
    const OccupancyUpdatePtr update = mapping.map(frame(t), nullptr, tf_, ros::Time(t), &result);
    ASSERT_TRUE(update) << result.why;
    ASSERT_TRUE(fusion.fuse(*update, &why)) << why;
    ASSERT_TRUE(plain.fuse(*update, &why)) << why;
    const size_t leaves = fusion.map().tree().getNumLeafNodes();
    if (k <= maintaining) EXPECT_EQ(leaves, plain.map().tree().getNumLeafNodes()) << "update " << k;
    // mergeSteps() steps at most (fewer when the parts do not divide evenly).
    const int steps_done = k - maintaining;
    if (k < maintaining) EXPECT_FALSE(fusion.mission().mergesQueued()) << "update " << k;
    if (steps_done >= 0 && steps_done < static_cast<int>(MissionMap::kMergeSteps) / 2)
      EXPECT_TRUE(fusion.mission().mergesQueued()) << "update " << k;
  }
  EXPECT_EQ(fusion.mission().mergeSteps(), MissionMap::kMergeSteps);
  EXPECT_FALSE(fusion.mission().mergesQueued());
  const octomap::OcTree& merged = fusion.map().tree();
  EXPECT_LT(merged.getNumLeafNodes(), plain.map().tree().getNumLeafNodes() * 3 / 4);
  size_t cells = 0;
  for (auto it = plain.map().tree().begin_leafs(), end = plain.map().tree().end_leafs(); it != end; ++it, ++cells) {
    const octomap::OcTreeNode* n = merged.search(it.getKey());
    ASSERT_NE(n, nullptr);
    ASSERT_EQ(n->getLogOdds(), it->getLogOdds());
  }
  EXPECT_GT(cells, 10000u);
}

// Pruning follows the updates' stamps, so that a replay prunes where the flight did.
TEST_F(PipelineTest, TheMapIsPrunedOnTheUpdatesClock) {
  OctomapAccumulatorParameters params;
  params.map.max_extent_m = 5.0;  // the wall, 12 m ahead of the camera, is beyond it
  params.prune_period_s = 2.0;
  FrameMapping mapping{DisparityMapperParameters()};
  MapFusion fusion{params};
  std::string why;
  FrameResult result;
  for (double t : {10.0, 11.0, 12.5}) {
    const OccupancyUpdatePtr update = mapping.map(frame(t), nullptr, tf_, ros::Time(t), &result);
    ASSERT_TRUE(update) << result.why;
    ASSERT_TRUE(fusion.fuse(*update, &why)) << why;
    if (t < 12.0) EXPECT_EQ(fusion.counters().leaves_pruned, 0u) << t;  // less than 2 s of updates
  }
  EXPECT_GT(fusion.counters().leaves_pruned, 0u);
  EXPECT_EQ(fusion.map().tree().search(12.1, 0.1, 2.1), nullptr);
}

namespace {

/// @p value as a parameter's text: whole numbers without a fraction (int parameters take no "1.000000").
std::string parameterText(double value) {
  char text[64];
  if (value == std::floor(value) && std::abs(value) < 1e15)
    std::snprintf(text, sizeof text, "%.0f", value);
  else
    std::snprintf(text, sizeof text, "%.17g", value);
  return text;
}

/// Each numeric parameter of @p Params at both ends of its range, the rest at their defaults.
template <typename Params>
std::vector<std::pair<std::string, std::string>> rangeEnds() {
  std::vector<std::pair<std::string, std::string>> ends;
  Params defaults;
  Params::forEachParameter(defaults, [&](const ParameterSpec& spec, const auto&) {
    if (std::isnan(spec.min)) return;  // a text, flag or choice
    ends.emplace_back(spec.name, parameterText(spec.min));
    ends.emplace_back(spec.name, parameterText(spec.max));
  });
  return ends;
}

/// Both nodelets' parameters with @p name at @p value, the rest at their
/// defaults; false (and the reason checked to name it) for an end that
/// conflicts with another default, such as max_range_m at its lowest against min_range_m.
bool loadEnd(const std::string& name, const std::string& value, DisparityMapperParameters* mapper,
             OctomapAccumulatorParameters* accumulator) {
  std::string why;
  if (loadParameters({{name, value}}, mapper, accumulator, &why)) return true;
  EXPECT_NE(why.find(name), std::string::npos) << name << "=" << value << ": " << why;
  std::printf("  %s=%s: refused by the table (%s)\n", name.c_str(), value.c_str(), why.c_str());
  return false;
}

}  // namespace

// Every value a user may set, by the ranges of the one parameter table, maps
// the wall or is refused with a reason: no exception, no box beyond
// max_grid_cells nor 8 times the defaults' (σ_angle 0.5 rad, the top of its
// range, once took 43 s and 1 GB an image). Each end's time is printed, not asserted.
TEST_F(PipelineTest, EveryNumberParameterAtTheEndsOfItsRangeMapsOrRefuses) {
  size_t mapped = 0, refused = 0, fused = 0;
  std::set<std::string> not_mapped, not_fused;
  double stamp_s = 100.0;
  // Memory: no end may grow the frame's box past this many times the
  // defaults' (the σ tops, padded by the capped blur, grow it 4.1-fold;
  // uncapped, σ_angle 0.5 rad grew it 97-fold and took 55 s).
  constexpr size_t kMaxBoxGrowth = 8;
  FrameMapping defaults{DisparityMapperParameters()};
  FrameResult default_result;
  const OccupancyUpdatePtr default_update =
      defaults.map(frame(stamp_s), nullptr, tf_, ros::Time(stamp_s + 0.001), &default_result);
  ASSERT_TRUE(default_update) << default_result.why;
  const size_t default_cells =
      static_cast<size_t>(default_update->size[0]) * default_update->size[1] * default_update->size[2];
  for (const auto& [name, value] : rangeEnds<DisparityMapperParameters>()) {
    DisparityMapperParameters mapper;
    OctomapAccumulatorParameters accumulator;
    if (!loadEnd(name, value, &mapper, &accumulator)) {
      ++refused;
      not_mapped.insert(name);
      continue;
    }
    FrameMapping mapping(mapper);
    FrameResult result;
    stamp_s += 1.0;
    const auto start = std::chrono::steady_clock::now();
    OccupancyUpdatePtr update;
    ASSERT_NO_THROW(update = mapping.map(frame(stamp_s), nullptr, tf_, ros::Time(stamp_s + 0.001), &result))
        << name << "=" << value;
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - start).count();
    if (update) {
      ++mapped;
      const size_t cells = static_cast<size_t>(update->size[0]) * update->size[1] * update->size[2];
      EXPECT_LE(cells, mapper.drawing.max_grid_cells) << name << "=" << value;
      EXPECT_LE(cells, kMaxBoxGrowth * default_cells) << name << "=" << value;
      std::printf("  %s=%s: mapped, %.1f ms, %zu cells in the box, %zu carried\n", name.c_str(), value.c_str(), ms,
                  cells, update->log_odds.size());
    } else {
      ++refused;
      not_mapped.insert(name);
      EXPECT_FALSE(result.why.empty()) << name << "=" << value << " gave nothing and no reason";
      std::printf("  %s=%s: refused (%s), %.1f ms\n", name.c_str(), value.c_str(), result.why.c_str(), ms);
    }
  }
  // The accumulator's ends, each fusing the default mapper's update.
  FrameMapping mapping{DisparityMapperParameters()};
  FrameResult result;
  const OccupancyUpdatePtr update =
      mapping.map(frame(stamp_s + 1.0), nullptr, tf_, ros::Time(stamp_s + 1.001), &result);
  ASSERT_TRUE(update) << result.why;
  for (const auto& [name, value] : rangeEnds<OctomapAccumulatorParameters>()) {
    DisparityMapperParameters mapper;
    OctomapAccumulatorParameters accumulator;
    if (!loadEnd(name, value, &mapper, &accumulator)) {
      not_fused.insert(name);
      continue;
    }
    MapFusion fusion(accumulator);
    std::string why;
    bool took = false;
    ASSERT_NO_THROW(took = fusion.fuse(*update, &why)) << name << "=" << value;
    if (took) {
      ++fused;
    } else {
      not_fused.insert(name);
      EXPECT_FALSE(why.empty()) << name << "=" << value;
      std::printf("  accumulator %s=%s: refused the update (%s)\n", name.c_str(), value.c_str(), why.c_str());
    }
  }
  std::printf("range ends: %zu mapped, %zu refused; accumulator: %zu fused\n", mapped, refused, fused);
  // Every other end maps: the σ tops among them (uncapped, their padded
  // grid went past max_grid_cells), and each of these is refused at one end
  // only, for the reason printed above (a grid past max_grid_cells, p_sky
  // below p_free, a principal point far outside the image, an image of more
  // pixels than allowed; an update of another resolution or box, a
  // threshold outside the clamping bounds, an empty band).
  EXPECT_EQ(not_mapped, (std::set<std::string>{"max_range_m", "resolution_m", "p_free", "p_sky", "cx_px", "cy_px",
                                               "max_image_pixels"}));
  EXPECT_EQ(refused, not_mapped.size());
  EXPECT_EQ(not_fused, (std::set<std::string>{"resolution_m", "max_update_cells", "occupancy_threshold_prob",
                                              "projection_min_z_m", "projection_max_z_m"}));
}
