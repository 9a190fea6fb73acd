#include "stereo_occupancy/store/tile_store.h"

#include <sqlite3.h>

#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstring>
#include <sstream>
#include <stdexcept>

#include "stereo_occupancy/accumulating_octree.h"

namespace stereo_occupancy {

namespace {

/// Bumped when a tile's row changes meaning; a database of another format is refused.
constexpr const char* kFormat = "stereo_occupancy tiles 1";
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

std::vector<MapAccumulator::Leaf> deserialise(const std::string& bytes, double resolution_m) {
  std::istringstream in(bytes);
  auto tree = std::make_unique<octomap::OcTree>(resolution_m);
  if (!tree->readData(in) || in.fail()) throw std::runtime_error("a tile row is not OcTree data");
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

TileStore::TileStore(const std::string& path, double resolution_m) : path_(path), resolution_m_(resolution_m) {
  auto fail = [&](const std::string& why) {
    if (db_) sqlite3_close(db_);
    db_ = nullptr;
    throw std::runtime_error("tile database '" + path + "': " + why);
  };
  if (sqlite3_open_v2(path.c_str(), &db_, SQLITE_OPEN_READWRITE | SQLITE_OPEN_CREATE | SQLITE_OPEN_FULLMUTEX,
                      nullptr) != SQLITE_OK)
    fail(db_ ? sqlite3_errmsg(db_) : "cannot open");
  try {
    // Exclusive: a second accumulator on the same file would overwrite
    // tiles it never loaded. WAL: a crash never leaves a half-written row.
    execute("PRAGMA locking_mode = EXCLUSIVE");
    execute("PRAGMA journal_mode = WAL");
    execute("PRAGMA synchronous = NORMAL");
    if (sqlite3_exec(db_, "BEGIN EXCLUSIVE", nullptr, nullptr, nullptr) != SQLITE_OK)
      fail(sqlite3_errcode(db_) == SQLITE_BUSY ? "locked: another process has it open"
                                                : std::string(sqlite3_errmsg(db_)));
    execute("CREATE TABLE IF NOT EXISTS meta (key TEXT PRIMARY KEY, value TEXT NOT NULL)");
    execute("CREATE TABLE IF NOT EXISTS tiles (x INTEGER NOT NULL, y INTEGER NOT NULL, z INTEGER NOT NULL, "
            "leaves INTEGER NOT NULL, octree BLOB NOT NULL, PRIMARY KEY (x, y, z)) WITHOUT ROWID");
    std::map<std::string, std::string> meta;
    {
      Statement read(db_, "SELECT key, value FROM meta");
      while (sqlite3_step(read.get()) == SQLITE_ROW)
        meta[reinterpret_cast<const char*>(sqlite3_column_text(read.get(), 0))] =
            reinterpret_cast<const char*>(sqlite3_column_text(read.get(), 1));
    }
    if (meta.empty() && resolution_m <= 0.0) {
      fail("not a tile database (no resolution_m)");
    } else if (meta.empty()) {
      Statement insert(db_, "INSERT INTO meta (key, value) VALUES (?, ?)");
      const std::string resolution = std::to_string(resolution_m);
      for (const auto& kv : {std::make_pair(std::string("format"), std::string(kFormat)),
                             std::make_pair(std::string("resolution_m"), resolution)}) {
        sqlite3_bind_text(insert.get(), 1, kv.first.c_str(), -1, SQLITE_TRANSIENT);
        sqlite3_bind_text(insert.get(), 2, kv.second.c_str(), -1, SQLITE_TRANSIENT);
        insert.run();
      }
    } else if (meta["format"] != kFormat) {
      fail("not a tile database of this version (format '" + meta["format"] + "')");
    } else if (resolution_m <= 0.0) {
      resolution_m_ = std::stod(meta["resolution_m"]);
    } else if (std::abs(std::stod(meta["resolution_m"]) - resolution_m) > 1e-9 * resolution_m) {
      fail("its tiles have " + meta["resolution_m"] + " m cells, the map " + std::to_string(resolution_m) + " m");
    }
    execute("COMMIT");
    Statement list(db_, "SELECT x, y, z FROM tiles");
    while (sqlite3_step(list.get()) == SQLITE_ROW)
      stored_.insert(pack(TileIndex(sqlite3_column_int(list.get(), 0), sqlite3_column_int(list.get(), 1),
                                        sqlite3_column_int(list.get(), 2))));
  } catch (const std::runtime_error& e) {
    if (!db_) throw;
    fail(e.what());
  }
  writer_ = std::thread([this] { writerLoop(); });
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
  bytes->assign(static_cast<const char*>(sqlite3_column_blob(read.get(), 0)),
                static_cast<size_t>(sqlite3_column_bytes(read.get(), 0)));
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
