#pragma once
/// @file
/// The mission's tiles on disk: an SQLite database (as RTAB-Map keeps its
/// maps), one row per tile, each row an OctoMap .ot stream of the tile's
/// leaves. Writes happen on the store's own thread, so the fusion never
/// waits for the disk.

#include <atomic>
#include <condition_variable>
#include <cstdint>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>
#include <unordered_set>
#include <utility>
#include <vector>

#include "stereo_occupancy/map_accumulator.h"

struct sqlite3;

namespace stereo_occupancy {

/// What a TileStore has done.
struct TileStoreStatus {
  uint64_t tiles_written = 0;  ///< tile rows committed since the store opened
  uint64_t writes_failed = 0;  ///< batches that could not be committed (retried)
  size_t queued = 0;           ///< tiles waiting to be written
  std::string last_error;      ///< the last failure's reason; empty if none
  size_t damaged_rows = 0;     ///< rows found damaged when the store opened (see TileStore())
  std::string first_damage;    ///< the first of them: its tile and what is wrong
};

/// A stored tile's row as the streaming writer needs it (TileStore::rows).
struct TileRow {
  MapAccumulator::TileIndex tile;
  size_t nodes = 0;           ///< nodes of the tile's subtree (the tile's node and all below)
  float max_log_odds = 0.0f;  ///< the tile node's value: its leaves' largest log-odds
};

/// A database of map tiles (MapAccumulator::TileIndex -> leaves). Thread-safe.
class TileStore {
 public:
  using TileIndex = MapAccumulator::TileIndex;
  using Leaf = MapAccumulator::Leaf;

  /// How a TileStore opens its database.
  enum class Access {
    kReadWrite,  ///< creates it if missing; damaged rows are moved aside (see TileStore())
    kReadOnly,   ///< never writes the file (tools that only read); put() and clear() throw
  };

  /// Opens or creates the database at @p path for maps of @p resolution_m
  /// cells (0: an existing database's) and locks it for this process. Every
  /// row is checked as it opens (checkOcTreeData: O(the database's size));
  /// with kReadWrite, damaged rows move to the table damaged_tiles (kept for
  /// inspection) and their tiles start empty: status() counts them.
  /// @throws std::runtime_error naming the file and the reason: it cannot be
  /// created or read, another process has it open ("locked"), it is not a
  /// tile database (another program's SQLite file is never changed), its
  /// meta entries are missing or not numbers, its tiles have another
  /// resolution, its -wal file belongs to another database (detected for
  /// databases of this version: each holds a random mission id that every
  /// commit writes into its log; the files are then left as they are), or
  /// (kReadOnly) a row is damaged.
  TileStore(const std::string& path, double resolution_m, Access access = Access::kReadWrite);
  /// Writes what is queued (a failure goes to stderr), then closes.
  ~TileStore();
  TileStore(const TileStore&) = delete;
  TileStore& operator=(const TileStore&) = delete;

  /// Deletes the tile database at @p path (and its -wal and -shm files)
  /// while holding its lock, so that one a running accumulator holds is never
  /// removed; nothing if there is no file.
  /// @throws std::runtime_error if it is locked or not a tile database (another program's file stays).
  static void removeDatabase(const std::string& path);

  /// @p tile packed into 64 bits (16 per axis), and back: the key of sets and maps of tiles.
  static uint64_t pack(const TileIndex& tile);
  static TileIndex unpack(uint64_t key);

  const std::string& path() const { return path_; }
  double resolution() const { return resolution_m_; }

  /// Queues @p leaves as @p tile's whole content (none: the tile is deleted).
  /// The store's thread writes it; until then get() returns it from memory.
  void put(const TileIndex& tile, std::vector<Leaf> leaves);
  /// @p tile's content, queued or stored; false if the store has none.
  /// @throws std::runtime_error if the row cannot be read.
  bool get(const TileIndex& tile, std::vector<Leaf>* leaves) const;
  /// Every tile the store has (queued or stored).
  std::vector<TileIndex> tiles() const;
  /// The stored rows' summaries, read without their data (after flush(): every tile).
  std::vector<TileRow> rows() const;
  /// A stored row's data: OcTree::writeData of a tree holding only the tile,
  /// so kTileDepth path nodes (kRowNodeBytes each) and then the tile's subtree
  /// in pre-order. False if there is no row. @throws std::runtime_error on a
  /// read error or a damaged row (naming the tile).
  bool rowData(const TileIndex& tile, std::string* bytes) const;
  /// Bytes per node in a row (OcTreeNode::writeData's float, then the child bits).
  static constexpr size_t kRowNodeBytes = sizeof(float) + 1;
  /// Moves @p tile's stored row to the table damaged_tiles with @p why (for
  /// a row get() found damaged after the store opened): the tile is then
  /// empty. Nothing if the tile has a queued content or no row.
  void setAside(const TileIndex& tile, const std::string& why);
  /// Waits until everything queued is committed, or a write fails: then false.
  bool flush();
  /// Deletes every tile (queued ones too).
  void clear();
  TileStoreStatus status() const;

 private:
  struct Queued {
    TileIndex tile;
    std::shared_ptr<const std::vector<Leaf>> leaves;
    uint64_t version = 0;
  };
  void writerLoop();
  /// Commits @p batch in one transaction unless clear() came after it was
  /// taken (at @p generation); false with the reason in @p error.
  bool write(const std::vector<Queued>& batch, uint64_t generation, std::string* error);
  void execute(const char* sql);  ///< @throws std::runtime_error; requires db_mutex_
  /// Creates the tables in a new database or checks an existing one's meta
  /// entries (the constructor's part inside its first transaction).
  void openTables();
  /// The mission id (PRAGMA application_id) in @p path's own header, read
  /// without SQLite; 0 if no -wal file waits beside it or there is none.
  static uint32_t missionIdInFile(const std::string& path);
  /// Refuses a -wal file that SQLite replayed onto this database from another
  /// one: every commit writes page 1, so another mission's log carries its id.
  void checkWalBelongs(uint32_t file_mission);
  /// A random positive mission id into the header (PRAGMA application_id).
  void setMissionId();
  /// Checks every row; moves the damaged ones aside (kReadWrite) or refuses them.
  void checkRows();
  /// Moves the rows of @p damaged (tile, reason) to damaged_tiles; requires db_mutex_ or the constructor.
  void moveAside(const std::vector<std::pair<TileIndex, std::string>>& damaged);
  /// Throws for a write on a kReadOnly store.
  void requireWritable(const char* what) const;

  std::string path_;
  double resolution_m_;
  Access access_;
  mutable std::mutex db_mutex_;  ///< the connection's; taken after mutex_ if both
  sqlite3* db_ = nullptr;
  uint64_t commits_ = 0;  ///< write() counts them into PRAGMA user_version; requires db_mutex_

  mutable std::mutex mutex_;  ///< guards everything below
  std::condition_variable wake_writer_, written_;
  std::map<uint64_t, Queued> queue_;     ///< by packed tile index
  std::unordered_set<uint64_t> stored_;  ///< tiles with a row
  uint64_t next_version_ = 1;
  std::atomic<uint64_t> generation_{0};  ///< clear() counts it up, under both locks
  bool writing_ = false, stop_ = false;
  TileStoreStatus status_;
  std::thread writer_;
};

}  // namespace stereo_occupancy
