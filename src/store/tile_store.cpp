#include "stereo_occupancy/store/tile_store.h"

#include <sqlite3.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <fstream>
#include <random>
#include <sstream>
#include <stdexcept>

#include "stereo_occupancy/accumulating_octree.h"
#include "stereo_occupancy/octomap_io.h"

namespace stereo_occupancy {

namespace {

/// Bumped when a tile's row changes meaning; a database of another format is refused.
constexpr const char* kFormat = "stereo_occupancy tiles 1";
/// The SQLite file header's size and where it keeps PRAGMA application_id (big-endian).
constexpr size_t kSqliteHeaderBytes = 100;
constexpr size_t kApplicationIdOffset = 68;
/// A -wal file no longer than its header holds no frame to replay.
constexpr off_t kWalHeaderBytes = 32;
/// A failed write is tried again after this long [ms].
constexpr int kRetryMs = 1000;

/// TileStore::pack's offset: tile indices from -2^15 on.
constexpr int64_t kPackOffset = 1 << 15;

/// The tile's leaves as the data part of an OctoMap .ot file (OcTree::writeData:
/// every node's log-odds, inner nodes included), the header being the database's.
std::string serialise(const std::vector<MapAccumulator::Leaf>& leaves, double resolution_m) {
  AccumulatingOcTree tree(resolution_m);
  for (const auto& leaf : leaves) tree.setLeaf(leaf.key, leaf.depth, leaf.log_odds);
  tree.updateInnerOccupancy();
  std::ostringstream out;
  if (!tree.writeData(out)) throw std::runtime_error("cannot serialise a tile");
  return out.str();
}

/// Checks that @p bytes is a tile row: one whole tree (checkOcTreeData)
/// whose first kTileDepth nodes are the path to the tile, one child each.
/// @throws std::runtime_error saying what is wrong.
void checkRow(const std::string& bytes) {
  checkOcTreeData(bytes.data(), bytes.size(), OcTreeEncoding::kFull);
  const size_t path_bytes = MapAccumulator::kTileDepth * TileStore::kRowNodeBytes;
  if (bytes.size() <= path_bytes) throw std::runtime_error("it ends before its tile's node");
  for (size_t i = 0; i < MapAccumulator::kTileDepth; ++i) {
    const unsigned bits = static_cast<unsigned char>(bytes[i * TileStore::kRowNodeBytes + sizeof(float)]);
    if (bits == 0 || (bits & (bits - 1)) != 0) throw std::runtime_error("its path to the tile branches");
  }
}

std::vector<MapAccumulator::Leaf> deserialise(const std::string& bytes, double resolution_m) {
  const std::unique_ptr<octomap::OcTree> tree = readOcTreeData(bytes, OcTreeEncoding::kFull, resolution_m);
  std::vector<MapAccumulator::Leaf> leaves;
  leaves.reserve(tree->getNumLeafNodes());
  for (auto it = tree->begin_leafs(), end = tree->end_leafs(); it != end; ++it) {
    MapAccumulator::Leaf leaf;
    leaf.key = it.getKey();
    leaf.depth = static_cast<uint8_t>(it.getDepth());
    leaf.log_odds = it->getLogOdds();
    leaves.push_back(leaf);
  }
  return leaves;
}

/// A column's text; @throws std::runtime_error for NULL (another program's table).
std::string columnText(sqlite3_stmt* stmt, int column, const char* what) {
  const unsigned char* text = sqlite3_column_text(stmt, column);
  if (!text) throw std::runtime_error(std::string("its meta table has a NULL ") + what);
  return reinterpret_cast<const char*>(text);
}

/// "tile (x, y, z)" for messages.
std::string tileName(const MapAccumulator::TileIndex& t) {
  return "tile (" + std::to_string(t.x()) + ", " + std::to_string(t.y()) + ", " + std::to_string(t.z()) + ")";
}

/// @p text as a cell size [m]; @throws std::runtime_error unless a finite positive number.
double parseResolution(const std::string& text) {
  char* end = nullptr;
  const double value = std::strtod(text.c_str(), &end);
  if (text.empty() || end != text.c_str() + text.size() || !std::isfinite(value) || !(value > 0.0))
    throw std::runtime_error("its resolution_m entry '" + text + "' is not a positive number");
  return value;
}

/// A prepared statement, finalised on scope exit.
class Statement {
 public:
  Statement(sqlite3* db, const char* sql) : db_(db) {
    if (sqlite3_prepare_v2(db, sql, -1, &stmt_, nullptr) != SQLITE_OK)
      throw std::runtime_error(std::string(sqlite3_errmsg(db)) + " (" + sql + ")");
  }
  ~Statement() { sqlite3_finalize(stmt_); }
  Statement(const Statement&) = delete;
  Statement& operator=(const Statement&) = delete;
  sqlite3_stmt* get() { return stmt_; }
  void bindTile(const MapAccumulator::TileIndex& t) {
    for (int a = 0; a < 3; ++a) sqlite3_bind_int(stmt_, a + 1, t[a]);
  }
  /// Steps a statement that returns no rows; @throws std::runtime_error.
  void run() {
    if (sqlite3_step(stmt_) != SQLITE_DONE) throw std::runtime_error(sqlite3_errmsg(db_));
    sqlite3_reset(stmt_);
    sqlite3_clear_bindings(stmt_);
  }

 private:
  sqlite3* db_;
  sqlite3_stmt* stmt_ = nullptr;
};

}  // namespace

uint64_t TileStore::pack(const TileIndex& t) {
  return (static_cast<uint64_t>(t.x() + kPackOffset) << 32) | (static_cast<uint64_t>(t.y() + kPackOffset) << 16) |
         static_cast<uint64_t>(t.z() + kPackOffset);
}

TileStore::TileIndex TileStore::unpack(uint64_t key) {
  return TileIndex(static_cast<int>(static_cast<int64_t>(key >> 32) - kPackOffset),
                   static_cast<int>(static_cast<int64_t>((key >> 16) & 0xffff) - kPackOffset),
                   static_cast<int>(static_cast<int64_t>(key & 0xffff) - kPackOffset));
}

TileStore::TileStore(const std::string& path, double resolution_m, Access access)
    : path_(path), resolution_m_(resolution_m), access_(access) {
  auto fail = [&](const std::string& why) {
    if (db_) sqlite3_close(db_);
    db_ = nullptr;
    throw std::runtime_error("tile database '" + path + "': " + why);
  };
  const bool read_only = access == Access::kReadOnly;
  const int flags =
      (read_only ? SQLITE_OPEN_READONLY : SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE) | SQLITE_OPEN_FULLMUTEX;
  if (sqlite3_open_v2(path.c_str(), &db_, flags, nullptr) != SQLITE_OK) fail(db_ ? sqlite3_errmsg(db_) : "cannot open");
  try {
    // Exclusive: a second accumulator on the same file would overwrite
    // tiles it never loaded. A reader takes a shared lock, which a database
    // an accumulator holds refuses (SQLite needs the shared-memory WAL index
    // to read a WAL database without writing it).
    if (!read_only) execute("PRAGMA locking_mode = EXCLUSIVE");
    const uint32_t file_mission = missionIdInFile(path);  // before SQLite reads the -wal file
    if (sqlite3_exec(db_, read_only ? "BEGIN; SELECT count(*) FROM sqlite_master" : "BEGIN EXCLUSIVE", nullptr, nullptr,
                     nullptr) != SQLITE_OK)
      fail(sqlite3_errcode(db_) == SQLITE_BUSY ? "locked: another process has it open"
                                               : std::string(sqlite3_errmsg(db_)));
    checkWalBelongs(file_mission);
    openTables();  // before anything is written: another program's file stays as it was
    execute("COMMIT");
    if (!read_only) {
      // WAL: a crash never leaves a half-written row.
      execute("PRAGMA journal_mode = WAL");
      execute("PRAGMA synchronous = NORMAL");
    }
    checkRows();
  } catch (const std::exception& e) {  // std::bad_alloc too: the connection must not keep the file locked
    if (!db_) throw;
    fail(e.what());
  }
  writer_ = std::thread([this] { writerLoop(); });
}

uint32_t TileStore::missionIdInFile(const std::string& path) {
  struct stat wal;
  if (::stat((path + "-wal").c_str(), &wal) != 0 || wal.st_size <= kWalHeaderBytes) return 0;  // nothing to replay
  std::ifstream file(path, std::ios::binary);
  char header[kSqliteHeaderBytes];
  if (!file.read(header, sizeof header) || std::memcmp(header, "SQLite format 3", 16) != 0) return 0;
  const auto* b = reinterpret_cast<const unsigned char*>(header + kApplicationIdOffset);
  return (uint32_t{b[0]} << 24) | (uint32_t{b[1]} << 16) | (uint32_t{b[2]} << 8) | b[3];  // big-endian
}

void TileStore::checkWalBelongs(uint32_t file_mission) {
  if (file_mission == 0) return;  // no -wal file, or a database of before the mission id
  Statement read(db_, "PRAGMA application_id");
  if (sqlite3_step(read.get()) != SQLITE_ROW) throw std::runtime_error(sqlite3_errmsg(db_));
  const uint32_t replayed = static_cast<uint32_t>(sqlite3_column_int64(read.get(), 0));
  if (replayed == file_mission) return;
  // Closing would checkpoint the foreign log into the database: not this one.
  sqlite3_db_config(db_, SQLITE_DBCONFIG_NO_CKPT_ON_CLOSE, 1, nullptr);
  throw std::runtime_error("its -wal file belongs to another database (mission " + std::to_string(replayed) +
                           ", this one " + std::to_string(file_mission) + "); nothing was changed: move '" + path_ +
                           "-wal' away to open the database as it was last written whole");
}

void TileStore::openTables() {
  std::vector<std::string> tables;
  {
    Statement list(db_, "SELECT name FROM sqlite_master WHERE type = 'table'");
    while (sqlite3_step(list.get()) == SQLITE_ROW) {
      const unsigned char* name = sqlite3_column_text(list.get(), 0);
      tables.push_back(name ? reinterpret_cast<const char*>(name) : "");
    }
  }
  const auto has = [&](const char* table) { return std::find(tables.begin(), tables.end(), table) != tables.end(); };
  if (tables.empty()) {
    // Created only by a writer that knows its cells.
    if (resolution_m_ <= 0.0 || access_ == Access::kReadOnly) throw std::runtime_error("not a tile database (empty)");
    setMissionId();
    execute("CREATE TABLE meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)");
    execute(
        "CREATE TABLE tiles (x INTEGER NOT NULL, y INTEGER NOT NULL, z INTEGER NOT NULL, "
        "leaves INTEGER NOT NULL, octree BLOB NOT NULL, PRIMARY KEY (x, y, z)) WITHOUT ROWID");
    Statement insert(db_, "INSERT INTO meta (key, value) VALUES (?, ?)");
    const std::string resolution = std::to_string(resolution_m_);
    for (const auto& kv : {std::make_pair(std::string("format"), std::string(kFormat)),
                           std::make_pair(std::string("resolution_m"), resolution)}) {
      sqlite3_bind_text(insert.get(), 1, kv.first.c_str(), -1, SQLITE_TRANSIENT);
      sqlite3_bind_text(insert.get(), 2, kv.second.c_str(), -1, SQLITE_TRANSIENT);
      insert.run();
    }
    return;
  }
  // Another program's file is refused before anything is written to it.
  if (!has("meta") || !has("tiles")) {
    std::string names;
    for (const auto& t : tables) names += (names.empty() ? "" : ", ") + t;
    throw std::runtime_error("not a tile database (its tables: " + names + ")");
  }
  std::map<std::string, std::string> meta;
  {
    Statement read(db_, "SELECT key, value FROM meta");
    while (sqlite3_step(read.get()) == SQLITE_ROW)
      meta[columnText(read.get(), 0, "key")] = columnText(read.get(), 1, "value");
  }
  if (meta["format"] != kFormat)
    throw std::runtime_error("not a tile database of this version (format '" + meta["format"] + "')");
  const double stored_m = parseResolution(meta["resolution_m"]);
  if (resolution_m_ <= 0.0) {
    resolution_m_ = stored_m;
  } else if (std::abs(stored_m - resolution_m_) > 1e-9 * resolution_m_) {
    throw std::runtime_error("its tiles have " + meta["resolution_m"] + " m cells, the map " +
                             std::to_string(resolution_m_) + " m");
  }
  if (access_ == Access::kReadWrite) {
    Statement id(db_, "PRAGMA application_id");
    if (sqlite3_step(id.get()) == SQLITE_ROW && sqlite3_column_int64(id.get(), 0) == 0) setMissionId();
  }
  if (access_ == Access::kReadWrite)
    execute(
        "CREATE TABLE IF NOT EXISTS damaged_tiles (x INTEGER NOT NULL, y INTEGER NOT NULL, z INTEGER NOT NULL, "
        "octree BLOB, reason TEXT NOT NULL)");
}

void TileStore::setMissionId() {
  std::random_device random;
  uint32_t id = 0;
  while (id == 0 || id > 0x7fffffffu) id = random();  // positive: PRAGMA application_id takes a signed 32-bit value
  execute(("PRAGMA application_id = " + std::to_string(id)).c_str());
}

void TileStore::checkRows() {
  std::vector<std::pair<TileIndex, std::string>> damaged;
  {
    Statement list(db_, "SELECT x, y, z, octree FROM tiles");
    int rc;
    while ((rc = sqlite3_step(list.get())) == SQLITE_ROW) {
      const TileIndex tile(sqlite3_column_int(list.get(), 0), sqlite3_column_int(list.get(), 1),
                           sqlite3_column_int(list.get(), 2));
      const void* blob = sqlite3_column_blob(list.get(), 3);
      const std::string bytes(static_cast<const char*>(blob), blob ? sqlite3_column_bytes(list.get(), 3) : 0);
      try {
        checkRow(bytes);
        stored_.insert(pack(tile));
      } catch (const std::runtime_error& e) {
        damaged.emplace_back(tile, e.what());
      }
    }
    if (rc != SQLITE_DONE) throw std::runtime_error(sqlite3_errmsg(db_));
  }
  if (damaged.empty()) return;
  status_.damaged_rows = damaged.size();
  status_.first_damage = tileName(damaged.front().first) + ": " + damaged.front().second;
  if (access_ == Access::kReadOnly)
    throw std::runtime_error(std::to_string(damaged.size()) + " damaged tile rows, the first " + status_.first_damage);
  moveAside(damaged);
}

void TileStore::moveAside(const std::vector<std::pair<TileIndex, std::string>>& damaged) {
  // In one transaction: the rows stay for inspection, the map goes on without them.
  execute("BEGIN IMMEDIATE");
  Statement move(db_,
                 "INSERT INTO damaged_tiles (x, y, z, octree, reason) "
                 "SELECT x, y, z, octree, ? FROM tiles WHERE x = ? AND y = ? AND z = ?");
  Statement erase(db_, "DELETE FROM tiles WHERE x = ? AND y = ? AND z = ?");
  for (const auto& [tile, why] : damaged) {
    sqlite3_bind_text(move.get(), 1, why.c_str(), -1, SQLITE_TRANSIENT);
    for (int a = 0; a < 3; ++a) sqlite3_bind_int(move.get(), a + 2, tile[a]);
    move.run();
    erase.bindTile(tile);
    erase.run();
  }
  execute("COMMIT");
}

void TileStore::setAside(const TileIndex& tile, const std::string& why) {
  requireWritable("setAside");
  std::lock_guard<std::mutex> lock(mutex_);
  std::lock_guard<std::mutex> db_lock(db_mutex_);
  if (queue_.count(pack(tile)) || !stored_.count(pack(tile))) return;  // a new content replaces the row anyway
  moveAside({{tile, why}});
  stored_.erase(pack(tile));
  ++status_.damaged_rows;
  if (status_.first_damage.empty()) status_.first_damage = tileName(tile) + ": " + why;
}

void TileStore::removeDatabase(const std::string& path) {
  if (::access(path.c_str(), F_OK) != 0) return;
  sqlite3* db = nullptr;
  const int opened = sqlite3_open_v2(path.c_str(), &db, SQLITE_OPEN_READWRITE | SQLITE_OPEN_FULLMUTEX, nullptr);
  auto fail = [&](const std::string& why) {
    sqlite3_close(db);
    throw std::runtime_error("tile database '" + path + "' is not replaced: " + why);
  };
  if (opened != SQLITE_OK) fail(db ? sqlite3_errmsg(db) : "cannot open");
  // The lock, held until the close: no accumulator can open the file between the check and the unlink.
  if (sqlite3_exec(db, "PRAGMA locking_mode = EXCLUSIVE; BEGIN EXCLUSIVE", nullptr, nullptr, nullptr) != SQLITE_OK)
    fail(sqlite3_errcode(db) == SQLITE_BUSY ? "locked: another process has it open" : sqlite3_errmsg(db));
  sqlite3_stmt* format = nullptr;
  const bool ours =
      sqlite3_prepare_v2(db, "SELECT value FROM meta WHERE key = 'format'", -1, &format, nullptr) == SQLITE_OK &&
      sqlite3_step(format) == SQLITE_ROW && sqlite3_column_text(format, 0) &&
      std::string(reinterpret_cast<const char*>(sqlite3_column_text(format, 0))) == kFormat;
  sqlite3_finalize(format);
  if (!ours) fail("it is not a tile database of this version");
  for (const char* suffix : {"", "-wal", "-shm"}) ::unlink((path + suffix).c_str());
  sqlite3_exec(db, "ROLLBACK", nullptr, nullptr, nullptr);
  sqlite3_close(db);
}

void TileStore::requireWritable(const char* what) const {
  if (access_ == Access::kReadOnly)
    throw std::logic_error(std::string("TileStore::") + what + " on a read-only store ('" + path_ + "')");
}

TileStore::~TileStore() {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  wake_writer_.notify_all();
  writer_.join();
  if (!queue_.empty())
    std::fprintf(stderr, "TileStore: %zu tiles could not be written to %s: %s\n", queue_.size(), path_.c_str(),
                 status_.last_error.c_str());
  sqlite3_close(db_);
}

void TileStore::execute(const char* sql) {
  char* message = nullptr;
  if (sqlite3_exec(db_, sql, nullptr, nullptr, &message) != SQLITE_OK) {
    const std::string why = message ? message : sqlite3_errmsg(db_);
    sqlite3_free(message);
    throw std::runtime_error(why);
  }
}

void TileStore::put(const TileIndex& tile, std::vector<Leaf> leaves) {
  requireWritable("put");
  {
    std::lock_guard<std::mutex> lock(mutex_);
    Queued& q = queue_[pack(tile)];
    q.tile = tile;
    q.leaves = std::make_shared<const std::vector<Leaf>>(std::move(leaves));
    q.version = next_version_++;
  }
  wake_writer_.notify_one();
}

bool TileStore::get(const TileIndex& tile, std::vector<Leaf>* leaves) const {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = queue_.find(pack(tile));
    if (it != queue_.end()) {
      *leaves = *it->second.leaves;
      return !leaves->empty();
    }
    if (!stored_.count(pack(tile))) return false;
  }
  std::string bytes;
  if (!rowData(tile, &bytes)) return false;
  *leaves = deserialise(bytes, resolution_m_);
  return true;
}

std::vector<TileStore::TileIndex> TileStore::tiles() const {
  std::lock_guard<std::mutex> lock(mutex_);
  std::unordered_set<uint64_t> all = stored_;
  std::vector<TileIndex> tiles;
  for (const auto& kv : queue_) {
    if (kv.second.leaves->empty())
      all.erase(kv.first);
    else
      all.insert(kv.first);
  }
  for (uint64_t key : all) tiles.push_back(unpack(key));
  return tiles;
}

std::vector<TileRow> TileStore::rows() const {
  std::lock_guard<std::mutex> lock(db_mutex_);
  Statement list(db_, "SELECT x, y, z, length(octree), substr(octree, 1, 4) FROM tiles");
  std::vector<TileRow> rows;
  int rc;
  while ((rc = sqlite3_step(list.get())) == SQLITE_ROW) {
    TileRow row;
    row.tile = TileIndex(sqlite3_column_int(list.get(), 0), sqlite3_column_int(list.get(), 1),
                         sqlite3_column_int(list.get(), 2));
    const size_t bytes = static_cast<size_t>(sqlite3_column_int64(list.get(), 3));
    const size_t path_bytes = MapAccumulator::kTileDepth * kRowNodeBytes;
    if (bytes <= path_bytes || bytes % kRowNodeBytes != 0 || sqlite3_column_bytes(list.get(), 4) != sizeof(float))
      throw std::runtime_error("tile database '" + path_ + "': a row is not tile data");
    row.nodes = (bytes - path_bytes) / kRowNodeBytes;
    std::memcpy(&row.max_log_odds, sqlite3_column_blob(list.get(), 4), sizeof(float));
    rows.push_back(row);
  }
  if (rc != SQLITE_DONE) throw std::runtime_error("tile database '" + path_ + "': " + sqlite3_errmsg(db_));
  return rows;
}

bool TileStore::rowData(const TileIndex& tile, std::string* bytes) const {
  std::lock_guard<std::mutex> lock(db_mutex_);
  Statement read(db_, "SELECT octree FROM tiles WHERE x = ? AND y = ? AND z = ?");
  read.bindTile(tile);
  const int rc = sqlite3_step(read.get());
  if (rc == SQLITE_DONE) return false;
  if (rc != SQLITE_ROW) throw std::runtime_error("tile database '" + path_ + "': " + sqlite3_errmsg(db_));
  const void* blob = sqlite3_column_blob(read.get(), 0);
  bytes->assign(static_cast<const char*>(blob), blob ? static_cast<size_t>(sqlite3_column_bytes(read.get(), 0)) : 0);
  try {
    checkRow(*bytes);
  } catch (const std::runtime_error& e) {
    throw std::runtime_error("tile database '" + path_ + "': the row of " + tileName(tile) +
                             " is damaged: " + e.what());
  }
  return true;
}

bool TileStore::flush() {
  std::unique_lock<std::mutex> lock(mutex_);
  const uint64_t failed_before = status_.writes_failed;
  wake_writer_.notify_one();
  written_.wait(lock, [&] { return (queue_.empty() && !writing_) || status_.writes_failed > failed_before; });
  return status_.writes_failed == failed_before;
}

void TileStore::clear() {
  requireWritable("clear");
  std::lock_guard<std::mutex> lock(mutex_);
  std::lock_guard<std::mutex> db_lock(db_mutex_);
  execute("DELETE FROM tiles");
  ++generation_;  // a batch taken before is not written
  queue_.clear();
  stored_.clear();
}

TileStoreStatus TileStore::status() const {
  std::lock_guard<std::mutex> lock(mutex_);
  TileStoreStatus s = status_;
  s.queued = queue_.size();
  return s;
}

void TileStore::writerLoop() {
  std::unique_lock<std::mutex> lock(mutex_);
  for (;;) {
    wake_writer_.wait(lock, [&] { return stop_ || !queue_.empty(); });
    if (queue_.empty()) return;  // stopped, nothing left
    std::vector<Queued> batch;
    for (const auto& kv : queue_) batch.push_back(kv.second);
    const uint64_t generation = generation_;
    writing_ = true;
    lock.unlock();
    std::string error;
    const bool ok = write(batch, generation, &error);
    lock.lock();
    writing_ = false;
    if (generation != generation_) {
      // clear() came meanwhile: the batch is void
    } else if (ok) {
      for (const Queued& q : batch) {
        const uint64_t key = pack(q.tile);
        if (q.leaves->empty())
          stored_.erase(key);
        else
          stored_.insert(key);
        auto it = queue_.find(key);
        if (it != queue_.end() && it->second.version == q.version) queue_.erase(it);  // not put again meanwhile
      }
      status_.tiles_written += batch.size();
    } else {
      ++status_.writes_failed;
      status_.last_error = error;
    }
    written_.notify_all();
    if (!ok) {
      if (stop_) return;  // the destructor reports what stays unwritten
      wake_writer_.wait_for(lock, std::chrono::milliseconds(kRetryMs), [&] { return stop_; });
    }
  }
}

bool TileStore::write(const std::vector<Queued>& batch, uint64_t generation, std::string* error) {
  // Serialised outside the connection's lock: get() may read meanwhile.
  std::vector<std::string> rows(batch.size());
  try {
    for (size_t i = 0; i < batch.size(); ++i)
      if (!batch[i].leaves->empty()) rows[i] = serialise(*batch[i].leaves, resolution_m_);
  } catch (const std::exception& e) {
    *error = e.what();
    return false;
  }
  std::lock_guard<std::mutex> lock(db_mutex_);
  if (generation != generation_) return true;  // cleared since the batch was taken
  try {
    execute("BEGIN IMMEDIATE");
    // Page 1, which holds the mission id, goes into the log with every
    // commit: a log replayed onto another mission's database shows itself.
    execute(("PRAGMA user_version = " + std::to_string(++commits_ & 0x7fffffff)).c_str());
    Statement upsert(db_, "INSERT OR REPLACE INTO tiles (x, y, z, leaves, octree) VALUES (?, ?, ?, ?, ?)");
    Statement erase(db_, "DELETE FROM tiles WHERE x = ? AND y = ? AND z = ?");
    for (size_t i = 0; i < batch.size(); ++i) {
      if (batch[i].leaves->empty()) {
        erase.bindTile(batch[i].tile);
        erase.run();
        continue;
      }
      upsert.bindTile(batch[i].tile);
      sqlite3_bind_int64(upsert.get(), 4, static_cast<sqlite3_int64>(batch[i].leaves->size()));
      sqlite3_bind_blob(upsert.get(), 5, rows[i].data(), static_cast<int>(rows[i].size()), SQLITE_STATIC);
      upsert.run();
    }
    execute("COMMIT");
    return true;
  } catch (const std::exception& e) {
    *error = "tile database '" + path_ + "': " + e.what();
    sqlite3_exec(db_, "ROLLBACK", nullptr, nullptr, nullptr);
    return false;
  }
}

}  // namespace stereo_occupancy
