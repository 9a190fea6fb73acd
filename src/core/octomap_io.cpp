#include "stereo_occupancy/octomap_io.h"

#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <array>
#include <cerrno>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <ostream>
#include <sstream>
#include <stdexcept>
#include <streambuf>
#include <vector>

namespace stereo_occupancy {

namespace {
std::string directoryOf(const std::string& path) {
  const size_t slash = path.rfind('/');
  return slash == std::string::npos ? "." : (slash == 0 ? "/" : path.substr(0, slash));
}
}  // namespace

namespace {

/// OctoMap's keys have 16 bits: leaves lie at depth 16 at the deepest.
constexpr unsigned kMaxTreeDepth = 16;

/// The first lines OctoMap writes (AbstractOcTree::write, writeBinaryConst).
constexpr char kFullFileLine[] = "# Octomap OcTree file";
constexpr char kBinaryFileLine[] = "# Octomap OcTree binary file";
/// A header longer than this is not OctoMap's (it writes about 120 bytes).
constexpr size_t kMaxHeaderBytes = 4096;

[[noreturn]] void refuse(const std::string& why, size_t at) {
  throw std::runtime_error(why + " at byte " + std::to_string(at));
}

/// The children a node of the stream announces: for kFull the bit mask
/// (child i follows if bit i is set), for kBinary the two-bit codes
/// (01 occupied leaf, 10 free leaf, 11 inner node that follows, 00 none).
struct Children {
  unsigned inner = 0;   ///< children whose own records follow in the stream
  unsigned leaves = 0;  ///< kBinary: children that are leaves, told by their codes alone
};

}  // namespace

OcTreeDataShape checkOcTreeData(const char* data, size_t size, OcTreeEncoding encoding) {
  OcTreeDataShape shape;
  if (size == 0) return shape;
  const bool full = encoding == OcTreeEncoding::kFull;
  const size_t record = full ? sizeof(float) + 1 : 2;
  // pending[d]: records still to come of the children of the node at depth d.
  std::array<unsigned, kMaxTreeDepth + 1> pending{};
  unsigned depth = 0;  // of the record read next
  size_t at = 0;
  shape.nodes = 1;  // the root; every other node is counted by its parent
  for (;;) {
    if (size - at < record) refuse("the tree's data ends inside a node", at);
    Children children;
    if (full) {
      float log_odds;
      std::memcpy(&log_odds, data + at, sizeof log_odds);
      if (!std::isfinite(log_odds)) refuse("a node's log-odds is not a finite number", at);
      const unsigned bits = static_cast<unsigned char>(data[at + sizeof log_odds]);
      for (unsigned i = 0; i < 8; ++i) children.inner += (bits >> i) & 1u;
    } else {
      for (unsigned b = 0; b < 2; ++b) {
        const unsigned bits = static_cast<unsigned char>(data[at + b]);
        for (unsigned i = 0; i < 4; ++i) {
          const unsigned code = (bits >> (2 * i)) & 3u;
          children.inner += code == 3u;
          children.leaves += code == 1u || code == 2u;
        }
      }
      if (children.inner + children.leaves == 0) refuse("an inner node without children", at);
    }
    // An inner child of a .bt record needs a record of its own one level down.
    if (children.inner > 0 && depth + (full ? 1 : 2) > kMaxTreeDepth)
      refuse("a node deeper than OctoMap's " + std::to_string(kMaxTreeDepth) + " levels", at);
    at += record;
    shape.nodes += children.inner + children.leaves;
    shape.leaves += children.leaves;
    if (full && children.inner == 0) ++shape.leaves;  // a .ot record without children is a leaf
    pending[depth] = children.inner;
    // The next record: this node's first child, or the next sibling up the path.
    while (pending[depth] == 0) {
      if (depth == 0) {
        if (at != size) refuse("data after the tree's end (" + std::to_string(size - at) + " bytes)", at);
        return shape;
      }
      --depth;
    }
    --pending[depth];
    ++depth;
  }
}

std::unique_ptr<octomap::OcTree> readOcTreeData(const std::string& bytes, OcTreeEncoding encoding,
                                                double resolution_m) {
  const OcTreeDataShape shape = checkOcTreeData(bytes.data(), bytes.size(), encoding);
  auto tree = std::make_unique<octomap::OcTree>(resolution_m);
  if (bytes.empty()) return tree;
  std::istringstream in(bytes);
  const bool read =
      static_cast<bool>(encoding == OcTreeEncoding::kFull ? tree->readData(in) : tree->readBinaryData(in));
  if (!read || tree->size() != shape.nodes) throw std::runtime_error("OctoMap could not read the tree's data");
  return tree;
}

std::unique_ptr<octomap::OcTree> readOcTreeFile(const std::string& path) {
  auto fail = [&](const std::string& why) -> std::runtime_error {
    return std::runtime_error("cannot read '" + path + "' as an OcTree map file (.bt or .ot): " + why);
  };
  std::ifstream file(path, std::ios::binary);
  if (!file) throw fail(std::strerror(errno));
  std::string bytes((std::istreambuf_iterator<char>(file)), std::istreambuf_iterator<char>());
  if (file.bad()) throw fail("read error");
  // The header, as OctoMap's readers take it: a first line that names the
  // encoding, then "id", "size", "res" lines (and comments), then "data".
  size_t at = 0;
  auto nextLine = [&](std::string* line) {
    const size_t end = bytes.find('\n', at);
    if (end == std::string::npos || end >= kMaxHeaderBytes) return false;
    *line = bytes.substr(at, end - at);
    at = end + 1;
    return true;
  };
  std::string line;
  if (!nextLine(&line)) throw fail("no OctoMap header");
  OcTreeEncoding encoding;
  if (line.compare(0, sizeof kBinaryFileLine - 1, kBinaryFileLine) == 0)
    encoding = OcTreeEncoding::kBinary;
  else if (line.compare(0, sizeof kFullFileLine - 1, kFullFileLine) == 0)
    encoding = OcTreeEncoding::kFull;
  else
    throw fail("it does not start with OctoMap's \"" + std::string(kFullFileLine) + "\" or \"" + kBinaryFileLine +
               "\" line");
  std::string id;
  double resolution_m = 0.0;
  long long claimed_nodes = -1;
  for (;;) {
    if (!nextLine(&line)) throw fail("its header has no \"data\" line");
    std::istringstream words(line);
    std::string keyword;
    words >> keyword;
    if (keyword == "data") break;
    if (keyword == "id") words >> id;
    if (keyword == "res") words >> resolution_m;
    if (keyword == "size") words >> claimed_nodes;
  }
  if (id != "OcTree") throw fail("it holds a " + (id.empty() ? std::string("tree of no id") : id) + ", not an OcTree");
  if (!std::isfinite(resolution_m) || !(resolution_m > 0.0)) throw fail("its resolution is not a positive number");
  if (claimed_nodes < 0) throw fail("its header has no node count (\"size\")");
  bytes.erase(0, at);
  OcTreeDataShape shape;
  try {
    shape = checkOcTreeData(bytes.data(), bytes.size(), encoding);
  } catch (const std::runtime_error& e) {
    throw fail(std::string(e.what()) + " of its data (truncated or damaged)");
  }
  if (shape.nodes != static_cast<unsigned long long>(claimed_nodes))
    throw fail("its header claims " + std::to_string(claimed_nodes) + " nodes, its data holds " +
               std::to_string(shape.nodes) + " (truncated or damaged)");
  try {
    return readOcTreeData(bytes, encoding, resolution_m);
  } catch (const std::runtime_error& e) {
    throw fail(e.what());
  }
}

int removeStaleTemporaries(const std::string& path) {
  const size_t slash = path.rfind('/');
  const std::string dir = directoryOf(path);
  const std::string prefix = (slash == std::string::npos ? path : path.substr(slash + 1)) + ".tmp";
  DIR* d = ::opendir(dir.c_str());
  if (!d) return 0;
  std::vector<std::string> stale;
  while (const dirent* entry = ::readdir(d)) {
    const std::string name = entry->d_name;
    if (name.size() <= prefix.size() || name.compare(0, prefix.size(), prefix) != 0) continue;
    const std::string digits = name.substr(prefix.size());
    if (digits.size() > 9 || digits.find_first_not_of("0123456789") != std::string::npos) continue;
    const pid_t pid = static_cast<pid_t>(std::atol(digits.c_str()));
    if (pid > 0 && ::kill(pid, 0) != 0 && errno == ESRCH) stale.push_back(name);  // its writer is gone
  }
  ::closedir(d);
  int removed = 0;
  for (const std::string& name : stale) removed += std::remove((dir + "/" + name).c_str()) == 0 ? 1 : 0;
  return removed;
}

namespace {

/// An output stream buffer over a file descriptor that remembers the first
/// write error's errno (std::ofstream loses it), so that a full disk is
/// reported as "No space left on device", not as a bad stream.
class FileDescriptorBuffer : public std::streambuf {
 public:
  explicit FileDescriptorBuffer(int fd) : fd_(fd) { setp(buffer_, buffer_ + sizeof buffer_); }
  /// 0, or the errno of the first failed write.
  int error() const { return error_; }
  /// Writes what is buffered; false (error() set) if the file did not take it.
  bool flushAll() { return sync() == 0; }

 protected:
  int_type overflow(int_type c) override {
    if (sync() != 0) return traits_type::eof();
    if (!traits_type::eq_int_type(c, traits_type::eof())) {
      *pptr() = traits_type::to_char_type(c);
      pbump(1);
    }
    return traits_type::not_eof(c);
  }
  int sync() override {
    const char* p = pbase();
    while (error_ == 0 && p < pptr()) {
      const ssize_t n = ::write(fd_, p, static_cast<size_t>(pptr() - p));
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0)
        error_ = n < 0 ? errno : EIO;
      else
        p += n;
    }
    setp(buffer_, buffer_ + sizeof buffer_);
    return error_ == 0 ? 0 : -1;
  }

 private:
  int fd_;
  int error_ = 0;
  char buffer_[1 << 16];
};

/// Writes into @p tmp and syncs it to disk; "" or the reason it failed.
std::string writeAndSync(const std::function<bool(std::ostream&)>& write, const std::string& tmp) {
  const int fd = ::open(tmp.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0644);
  if (fd < 0) return std::strerror(errno);
  FileDescriptorBuffer buffer(fd);
  std::ostream out(&buffer);
  std::string error;
  bool written = false;
  try {
    written = write(out);
  } catch (const std::exception& e) {
    error = e.what();
  }
  out.flush();
  if (error.empty()) {  // else the writer's own reason
    if (!buffer.flushAll() || buffer.error() != 0)
      error = std::strerror(buffer.error());
    else if (!written || !out.good())
      error = "octomap could not serialise the tree";
    else if (::fsync(fd) != 0)
      error = std::string("fsync: ") + std::strerror(errno);
  }
  if (::close(fd) != 0 && error.empty()) error = std::string("close: ") + std::strerror(errno);
  return error;
}

}  // namespace

void writeOcTree(const octomap::OcTree& tree, const std::string& path) {
  const bool full = path.size() >= 3 && path.compare(path.size() - 3, 3, ".ot") == 0;
  const bool binary = path.size() >= 3 && path.compare(path.size() - 3, 3, ".bt") == 0;
  if (!full && !binary) throw std::runtime_error("'" + path + "': the map file must end in .ot or .bt");
  writeFileAtomically(path, [&](std::ostream& out) { return full ? tree.write(out) : tree.writeBinaryConst(out); });
}

void writeFileAtomically(const std::string& path, const std::function<bool(std::ostream&)>& write) {
  // Write a temporary file beside the target, sync it, then rename it into
  // place and sync the directory: a crash, a kill or a full disk during the
  // write leaves the previous file intact, and a renamed file is on disk.
  removeStaleTemporaries(path);
  const std::string tmp = path + ".tmp" + std::to_string(::getpid());
  const std::string error = writeAndSync(write, tmp);
  if (!error.empty()) {
    std::remove(tmp.c_str());
    throw std::runtime_error("cannot write '" + path + "': " + error);
  }
  if (std::rename(tmp.c_str(), path.c_str()) != 0) {
    const std::string reason = std::strerror(errno);
    std::remove(tmp.c_str());
    throw std::runtime_error("cannot rename '" + tmp + "' to '" + path + "': " + reason);
  }
  const int dir = ::open(directoryOf(path).c_str(), O_RDONLY | O_DIRECTORY | O_CLOEXEC);
  if (dir < 0 || ::fsync(dir) != 0) {
    const std::string reason = std::strerror(errno);
    if (dir >= 0) ::close(dir);
    throw std::runtime_error("wrote '" + path + "' but could not sync its directory: " + reason);
  }
  ::close(dir);
}

}  // namespace stereo_occupancy
