#include <gtest/gtest.h>

#include <octomap/OcTree.h>

#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <fstream>

#include "stereo_occupancy/octomap_io.h"

using namespace stereo_occupancy;

namespace {
std::string tempPath(const std::string& name) { return ::testing::TempDir() + "stereo_occupancy_" + name; }
}  // namespace

// A writer killed between writing its temporary file and renaming it leaves
// path.tmp<PID> behind; the next write removes those whose process is gone
// and keeps a live process's file and unrelated names.
TEST(OctomapIo, WriteRemovesTemporariesOfDeadWriters) {
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) ::_exit(0);
  ASSERT_EQ(::waitpid(child, nullptr, 0), child);  // reaped: its pid no longer exists
  const std::string path = tempPath("stale.bt");
  const std::string dead = path + ".tmp" + std::to_string(child);
  const std::string live = path + ".tmp" + std::to_string(::getppid());
  const std::string other = path + ".tmpnotes";
  for (const std::string& p : {dead, live, other}) std::ofstream(p) << "x";
  auto exists = [](const std::string& p) { return std::ifstream(p).good(); };
  octomap::OcTree tree(0.25);
  tree.updateNode(1.0, 2.0, 3.0, true);
  writeOcTree(tree, path);
  EXPECT_FALSE(exists(dead));
  EXPECT_TRUE(exists(live));
  EXPECT_TRUE(exists(other));
  EXPECT_TRUE(exists(path));
  EXPECT_FALSE(exists(path + ".tmp" + std::to_string(::getpid())));  // its own was renamed into place
  EXPECT_EQ(removeStaleTemporaries(path), 0);
  for (const std::string& p : {live, other, path}) std::remove(p.c_str());
}
