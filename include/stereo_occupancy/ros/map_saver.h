#pragma once
/// @file
/// The accumulated map on disk: the mission's database, ~save_map, the
/// periodic checkpoints and the save at shutdown (OctomapAccumulator's).

#include <ros/node_handle.h>
#include <ros/service_server.h>
#include <ros/wall_timer.h>
#include <std_srvs/Trigger.h>

#include <cstdint>
#include <functional>
#include <mutex>
#include <string>
#include <vector>

#include "stereo_occupancy/map_accumulator.h"
#include "stereo_occupancy/parameter_table.h"

namespace stereo_occupancy {

class MapFusion;

/// Where and how often the map is saved.
struct MapSaverConfig {
  /// Where ~save_map writes and the map is saved on shutdown, and where the
  /// mission's database <map_name>.db lives; empty: nowhere (and cells beyond max_extent_m are dropped).
  std::string save_dir;
  std::string map_name = "stereo_occupancy_map";  ///< file base name in save_dir
  /// Checkpoint this often: changed tiles to the database (or, without one, the map to its files); 0: never [s].
  double save_period_s = 5.0;

  /// The parameters (stereo_occupancy/parameter_table.h): f(spec, member) for each.
  template <typename Self, typename F>
  static void forEachParameter(Self& c, F&& f) {
    f(textParameter("save_dir",
                    "~save_map, the shutdown save and the mission's database <map_name>.db; empty: nowhere"),
      c.save_dir);
    f(textParameter("map_name", "file base name in save_dir: a plain name"), c.map_name);
    f(numberParameter("save_period_s", "s", 0.0, 86400.0,
                      "checkpoint the changed tiles to the database this often; 0: never"),
      c.save_period_s);
  }

  /// The ranges of forEachParameter(), a plain map_name (one that stays in save_dir).
  bool isValid(std::string* why) const;
};

/// Saves a MapFusion's map: the whole mission (the database's tiles and the
/// live map) to <save_dir>/<map_name>.bt and .ot, on request (~save_map), at
/// shutdown, and without a database every save_period_s; with one, every
/// save_period_s the changed tiles go to it instead.
///
/// Threading: the map is the owner's, guarded by the owner's fusion mutex;
/// every member here is guarded by it too. The callbacks (service, timer)
/// take it; the methods that say so require the caller to hold it.
class MapSaver {
 public:
  /// @param config valid (MapSaverConfig::isValid()).
  /// @param map the map's config (its occupancy threshold writes the files).
  /// @param fusion the map, guarded by @p fusion_mutex; both outlive the saver.
  /// @param note_problem told, under the fusion lock, what went wrong (the owner's diagnostics summary).
  /// @param log_name the logger's name (the nodelet's, as NODELET_* log).
  MapSaver(const MapSaverConfig& config, const MapAccumulatorConfig& map, MapFusion* fusion, std::mutex* fusion_mutex,
           std::function<void(const std::string&)> note_problem, const std::string& log_name);

  /// Opens <save_dir>/<map_name>.db for the mission's tiles (save_dir made if
  /// missing, one level); on failure logs why, and the map goes on without
  /// it (databaseProblem()). Before the callbacks start: takes no lock.
  void openDatabase();
  /// Advertises ~save_map on @p private_nh and, with save_dir and
  /// save_period_s, starts the checkpoints on @p nh (wall time).
  void advertise(ros::NodeHandle& nh, ros::NodeHandle& private_nh);

  /// Writes the whole map's files and returns their paths (.bt, .ot). With
  /// the database, its changed tiles go to it first and @p lock (on the
  /// fusion mutex, held) is let go while the files are written from it.
  /// Without one, but one was asked for and could not be opened, writes only
  /// the live map, to <map_name>_live_only.bt and .ot, and throws.
  /// @throws std::runtime_error; the previous files stay whole.
  std::vector<std::string> save(std::unique_lock<std::mutex>& lock);
  /// The save at shutdown, if there is somewhere to save and something was
  /// fused; reported on stderr (rosconsole may be gone) with the time it
  /// took. @p lock holds the fusion mutex.
  void saveOnShutdown(std::unique_lock<std::mutex>& lock);

  /// The next three require the fusion lock.
  uint64_t savesFailed() const { return saves_failed_; }
  /// The last save failed (a later one that succeeds clears it).
  bool lastSaveFailed() const { return last_save_failed_; }
  /// Why the database could not be opened; empty if it was or none was asked for.
  const std::string& databaseProblem() const { return database_problem_; }

 private:
  bool saveMap(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& response);
  /// The timer's work: a checkpoint to the database, or without one the map to its files if it changed.
  void checkpoint();
  void saveFailed(const std::string& problem);  ///< requires the fusion lock

  MapSaverConfig config_;
  double occupancy_threshold_prob_;
  MapFusion* fusion_;
  std::mutex* fusion_mutex_;
  std::function<void(const std::string&)> note_problem_;
  std::string log_name_;

  // Guarded by *fusion_mutex_.
  uint64_t saves_failed_ = 0;
  bool last_save_failed_ = false;  ///< diagnostics ERROR until a save succeeds again
  std::string database_problem_;
  size_t updates_at_last_save_ = 0;

  ros::ServiceServer save_srv_;
  ros::WallTimer save_timer_;
};

}  // namespace stereo_occupancy
