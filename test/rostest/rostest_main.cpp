// The rostests' main: gtest in a ROS node whose callbacks run on two threads
// while the test body waits for the nodelets' answers.

#include <gtest/gtest.h>
#include <ros/ros.h>

int main(int argc, char** argv) {
  ::testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "stereo_occupancy_rostest", ros::init_options::AnonymousName);
  ros::AsyncSpinner spinner(2);
  spinner.start();
  const int result = RUN_ALL_TESTS();
  ros::shutdown();
  return result;
}
