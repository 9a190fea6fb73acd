#pragma once
/// @file
/// What the rostests share: waiting for what the nodelets send back.

#include <ros/time.h>

#include <functional>
#include <mutex>

namespace stereo_occupancy {

/// Polls @p condition under @p mutex (the one the test's callbacks hold)
/// until it holds or @p seconds of wall time have passed; returns the last answer.
inline bool waitFor(std::mutex& mutex, const std::function<bool()>& condition, double seconds) {
  const ros::WallTime until = ros::WallTime::now() + ros::WallDuration(seconds);
  while (ros::WallTime::now() < until) {
    {
      std::lock_guard<std::mutex> lock(mutex);
      if (condition()) return true;
    }
    ros::WallDuration(0.02).sleep();
  }
  return false;
}

}  // namespace stereo_occupancy
