#include "stereo_occupancy/octomap_io.h"

#include <dirent.h>
#include <fcntl.h>
#include <signal.h>
#include <unistd.h>

#include <cerrno>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <functional>
#include <ostream>
#include <streambuf>
#include <stdexcept>
#include <vector>

namespace stereo_occupancy {

namespace {
std::string directoryOf(const std::string& path) {
  const size_t slash = path.rfind('/');
  return slash == std::string::npos ? "." : (slash == 0 ? "/" : path.substr(0, slash));
}
}  // namespace

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
      if (n <= 0) error_ = n < 0 ? errno : EIO;
      else p += n;
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
