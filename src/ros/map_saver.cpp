#include "stereo_occupancy/ros/map_saver.h"

#include <ros/console.h>
#include <sys/stat.h>

#include <cctype>
#include <chrono>
#include <cstdio>
#include <stdexcept>
#include <utility>

#include "stereo_occupancy/ros/mapping_pipeline.h"

namespace stereo_occupancy {

namespace {
/// Without the mission's database, saves write the live map under
/// <map_name> + this, never over the mission's own files.
constexpr const char* kLiveOnlySuffix = "_live_only";
/// A failing periodic save repeats its error at most this often [s].
constexpr double kSaveErrorThrottleS = 60.0;

/// A name that stays inside its directory: no '/', not "." or "..", no hidden file.
bool isPlainFileName(const std::string& name) {
  if (name.empty() || name[0] == '.') return false;
  for (char c : name)
    if (!(std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.')) return false;
  return true;
}
}  // namespace

bool MapSaverConfig::isValid(std::string* why) const {
  if (!parametersInRange(*this, why)) return false;
  if (!isPlainFileName(map_name)) {
    if (why) *why = "map_name must be a plain file name: letters, digits, '_', '-', '.', not starting with '.'";
    return false;
  }
  return true;
}

MapSaver::MapSaver(const MapSaverConfig& config, const MapAccumulatorConfig& map, MapFusion* fusion,
                   std::mutex* fusion_mutex, std::function<void(const std::string&)> note_problem,
                   const std::string& log_name)
    : config_(config),
      occupancy_threshold_prob_(map.occupancy_threshold_prob),
      fusion_(fusion),
      fusion_mutex_(fusion_mutex),
      note_problem_(std::move(note_problem)),
      log_name_(log_name) {}

void MapSaver::openDatabase() {
  const std::string path = config_.save_dir + "/" + config_.map_name + ".db";
  ::mkdir(config_.save_dir.c_str(), 0755);  // one level, if missing; any other problem shows in the open
  try {
    fusion_->openDatabase(path);
  } catch (const std::exception& e) {
    // The live map works without it; what leaves max_extent_m is then lost.
    database_problem_ = e.what();
    ROS_ERROR_NAMED(log_name_,
                    "%s; mapping goes on without it: cells beyond max_extent_m are dropped, and ~save_map "
                    "answers false and writes only the live map, to %s%s.bt and .ot",
                    e.what(), config_.map_name.c_str(), kLiveOnlySuffix);
    return;
  }
  const size_t tiles = fusion_->mission().store()->tiles().size();
  const TileStoreStatus status = fusion_->mission().store()->status();
  if (status.damaged_rows > 0)
    ROS_ERROR_NAMED(log_name_,
                    "%s: %zu damaged tile rows moved to its table damaged_tiles; those tiles start empty "
                    "(the first: %s)",
                    path.c_str(), status.damaged_rows, status.first_damage.c_str());
  ROS_INFO_NAMED(log_name_, "the mission's tiles are kept in %s (%s, %zu tiles)", path.c_str(),
                 tiles ? "continued" : "new", tiles);
}

void MapSaver::advertise(ros::NodeHandle& nh, ros::NodeHandle& private_nh) {
  save_srv_ = private_nh.advertiseService("save_map", &MapSaver::saveMap, this);
  if (config_.save_period_s > 0.0 && !config_.save_dir.empty()) {
    // Periodic checkpoints, so that a crash loses at most save_period_s of
    // mapping: the changed tiles to the database (its thread writes them),
    // or without one the whole map to its files.
    save_timer_ = nh.createWallTimer(ros::WallDuration(config_.save_period_s),
                                     [this](const ros::WallTimerEvent&) { checkpoint(); });
  }
}

void MapSaver::checkpoint() {
  std::unique_lock<std::mutex> lock(*fusion_mutex_);
  if (fusion_->mission().store()) {
    fusion_->mission().checkpoint();
    return;
  }
  if (fusion_->map().updates() == updates_at_last_save_) return;
  try {
    save(lock);
  } catch (const std::exception& e) {
    saveFailed(std::string("periodic save failed: ") + e.what());
    ROS_ERROR_THROTTLE_NAMED(kSaveErrorThrottleS, log_name_, "periodic save failed (the previous map file stays): %s",
                             e.what());
  }
}

std::vector<std::string> MapSaver::save(std::unique_lock<std::mutex>& lock) {
  std::shared_ptr<TileStore> store = fusion_->mission().store();
  std::vector<std::string> paths;
  if (store) {
    // The whole mission: the changed tiles to the database, then all its
    // tiles to the files, outside the lock (the fusion goes on meanwhile).
    fusion_->mission().checkpoint();
    const size_t updates = fusion_->map().updates();
    lock.unlock();
    std::string error;
    try {
      paths = MissionMap::saveStore(*store, config_.save_dir, config_.map_name, occupancy_threshold_prob_);
    } catch (const std::exception& e) {
      error = e.what();
    }
    lock.lock();
    if (!error.empty()) throw std::runtime_error(error);
    updates_at_last_save_ = updates;
  } else if (!database_problem_.empty()) {
    // The mission's files may hold more than this live map (the database
    // that could not be opened has the rest): never replaced by it.
    paths = fusion_->map().save(config_.save_dir, config_.map_name + kLiveOnlySuffix);
    throw std::runtime_error("the mission's database is not open (" + database_problem_ +
                             "): wrote only the live map, to " + paths[0] + " and " + paths[1] + "; " +
                             config_.map_name + ".bt and .ot stay as they were");
  } else {
    paths = fusion_->map().save(config_.save_dir, config_.map_name);
    updates_at_last_save_ = fusion_->map().updates();
  }
  last_save_failed_ = false;
  return paths;
}

bool MapSaver::saveMap(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response) {
  if (config_.save_dir.empty()) {
    response.success = false;
    response.message = "save_dir is not set";
    return true;
  }
  std::unique_lock<std::mutex> lock(*fusion_mutex_);
  try {
    const auto paths = save(lock);
    response.success = true;
    response.message = paths[0] + " " + paths[1];
    ROS_INFO_NAMED(log_name_, "saved the map: %s", response.message.c_str());
  } catch (const std::exception& e) {
    saveFailed(std::string("save failed: ") + e.what());
    response.success = false;
    response.message = e.what();
    ROS_ERROR_NAMED(log_name_, "could not save the map (the previous map file stays): %s", e.what());
  }
  return true;
}

void MapSaver::saveOnShutdown(std::unique_lock<std::mutex>& lock) {
  if (config_.save_dir.empty()) return;
  if (fusion_->map().updates() == 0) return;
  try {
    // On stderr: rosconsole may be gone at shutdown. The time tells how much
    // of roslaunch's wait before SIGTERM (--sigint-timeout, 15 s) it took.
    const auto start = std::chrono::steady_clock::now();
    const std::vector<std::string> paths = save(lock);
    const double seconds = std::chrono::duration<double>(std::chrono::steady_clock::now() - start).count();
    for (const auto& path : paths)
      std::fprintf(stderr, "OctomapAccumulator: saved the map of %lu updates to %s on shutdown (%.1f s)\n",
                   static_cast<unsigned long>(fusion_->map().updates()), path.c_str(), seconds);
  } catch (const std::exception& e) {
    std::fprintf(stderr, "OctomapAccumulator: could not save the map on shutdown (the previous map file stays): %s\n",
                 e.what());
  }
}

void MapSaver::saveFailed(const std::string& problem) {
  ++saves_failed_;
  last_save_failed_ = true;
  note_problem_(problem);
}

}  // namespace stereo_occupancy
