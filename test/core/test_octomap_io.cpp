#include <gtest/gtest.h>

#include <octomap/OcTree.h>

#include <sys/wait.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <fstream>
#include <iterator>
#include <limits>
#include <sstream>
#include <string>

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

namespace {

/// A tree with occupied and free leaves at several depths, some pruned.
octomap::OcTree sampleTree() {
  octomap::OcTree tree(0.25);
  for (int i = 0; i < 200; ++i) tree.updateNode(0.3 * (i % 17) - 2.0, 0.25 * (i % 13), 0.5 * (i % 5) - 1.0, i % 3 != 0);
  for (int i = 0; i < 64; ++i)  // a free block that prunes to one coarse leaf
    tree.updateNode(8.0 + 0.25 * (i % 4), 8.0 + 0.25 * ((i / 4) % 4), 8.0 + 0.25 * (i / 16), false);
  tree.updateInnerOccupancy();
  tree.prune();
  return tree;
}

std::string dataOf(const octomap::OcTree& tree, OcTreeEncoding encoding) {
  std::ostringstream out;
  if (encoding == OcTreeEncoding::kFull)
    tree.writeData(out);
  else
    tree.writeBinaryData(out);
  return out.str();
}

std::string readAll(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  return std::string((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
}

void writeBytes(const std::string& path, const std::string& bytes) {
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
}

/// The message readOcTreeFile throws for @p path, or "" if it reads it.
std::string refusal(const std::string& path) {
  try {
    readOcTreeFile(path);
  } catch (const std::runtime_error& e) {
    return e.what();
  }
  return "";
}

}  // namespace

// The walk counts the nodes and leaves OctoMap's own writer wrote, in both
// encodings, and OctoMap's reader then builds the same tree.
TEST(OcTreeData, TheCheckCountsWhatOctomapWrote) {
  const octomap::OcTree tree = sampleTree();
  ASSERT_GT(tree.getNumLeafNodes(), 100u);
  for (OcTreeEncoding encoding : {OcTreeEncoding::kFull, OcTreeEncoding::kBinary}) {
    const std::string bytes = dataOf(tree, encoding);
    const OcTreeDataShape shape = checkOcTreeData(bytes.data(), bytes.size(), encoding);
    EXPECT_EQ(shape.nodes, tree.size());
    EXPECT_EQ(shape.leaves, tree.getNumLeafNodes());
    const auto read = readOcTreeData(bytes, encoding, 0.25);
    EXPECT_EQ(dataOf(*read, encoding), bytes);
  }
  EXPECT_EQ(checkOcTreeData(nullptr, 0, OcTreeEncoding::kFull).nodes, 0u);  // the empty tree
}

// Every shorter prefix and every longer stream of a real tree's data is
// refused: a truncated or padded row never reads as a tree.
TEST(OcTreeData, EveryTruncationAndPaddingIsRefused) {
  const octomap::OcTree tree = sampleTree();
  for (OcTreeEncoding encoding : {OcTreeEncoding::kFull, OcTreeEncoding::kBinary}) {
    const std::string bytes = dataOf(tree, encoding);
    size_t refused = 0;
    for (size_t n = 1; n < bytes.size(); ++n) {
      try {
        checkOcTreeData(bytes.data(), n, encoding);
      } catch (const std::runtime_error&) {
        ++refused;
      }
    }
    EXPECT_EQ(refused, bytes.size() - 1);
    const std::string padded = bytes + std::string(1, '\0');
    EXPECT_THROW(checkOcTreeData(padded.data(), padded.size(), encoding), std::runtime_error);
  }
}

// What OctoMap 1.9.7's readers recurse into without end (2 MB of 0xff: every
// node has eight children) is refused at OctoMap's 16th level, at once and
// without memory; a NaN log-odds is refused too.
TEST(OcTreeData, HostileBytesAreRefusedAtTheDepthLimit) {
  const std::string ff(2 << 20, '\xff');
  for (OcTreeEncoding encoding : {OcTreeEncoding::kFull, OcTreeEncoding::kBinary}) {
    try {
      checkOcTreeData(ff.data(), ff.size(), encoding);
      ADD_FAILURE() << "0xff bytes were taken as a tree";
    } catch (const std::runtime_error& e) {
      const std::string why = e.what();
      // 0xffffffff is a NaN: the .ot walk stops at the root's value.
      EXPECT_NE(why.find(encoding == OcTreeEncoding::kFull ? "finite" : "16 levels"), std::string::npos) << why;
    }
  }
  // A finite value and eight children at every level: the depth limit.
  std::string deep;
  for (int level = 0; level < 18; ++level) deep += std::string("\0\0\0\0\x01", 5);
  try {
    checkOcTreeData(deep.data(), deep.size(), OcTreeEncoding::kFull);
    ADD_FAILURE() << "a chain of 18 levels was taken as a tree";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("16 levels"), std::string::npos) << e.what();
    EXPECT_NE(std::string(e.what()).find("at byte 80"), std::string::npos) << e.what();  // the 17th node
  }
  // 16 levels below the root hold: a chain down to a leaf at the finest depth.
  std::string chain = deep.substr(0, 16 * 5) + std::string("\0\0\0\0\0", 5);
  EXPECT_EQ(checkOcTreeData(chain.data(), chain.size(), OcTreeEncoding::kFull).nodes, 17u);
  std::string nan_root = dataOf(sampleTree(), OcTreeEncoding::kFull);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  std::memcpy(&nan_root[0], &nan, sizeof nan);
  EXPECT_THROW(checkOcTreeData(nan_root.data(), nan_root.size(), OcTreeEncoding::kFull), std::runtime_error);
}

// Map files: OctoMap's own .bt and .ot read back; a hostile, truncated or
// padded file, a false node count, another tree type or a resolution that
// is no cell size are refused with the file's name and the reason.
TEST(OcTreeData, MapFilesAreCheckedAgainstTheirHeader) {
  const octomap::OcTree tree = sampleTree();
  for (const std::string ext : {".bt", ".ot"}) {
    const std::string path = tempPath("checked" + ext);
    writeOcTree(tree, path);
    const auto read = readOcTreeFile(path);
    EXPECT_DOUBLE_EQ(read->getResolution(), 0.25);
    EXPECT_EQ(read->size(), ext == ".ot" ? tree.size() : read->size());
    EXPECT_EQ(read->getNumLeafNodes(), tree.getNumLeafNodes()) << ext;
    const std::string file = readAll(path);
    const size_t data = file.find("data\n") + 5;
    // Truncated at 3/4 of the data, as a copy cut short.
    writeBytes(path, file.substr(0, data + (file.size() - data) * 3 / 4));
    EXPECT_NE(refusal(path).find("truncated or damaged"), std::string::npos) << refusal(path);
    EXPECT_NE(refusal(path).find(path), std::string::npos) << refusal(path);
    writeBytes(path, file + "xx");
    EXPECT_NE(refusal(path).find("data after the tree's end"), std::string::npos) << refusal(path);
    // The header claims one node more than the data holds.
    const size_t size_at = file.find("size ") + 5, size_end = file.find('\n', size_at);
    const unsigned long claimed = std::stoul(file.substr(size_at, size_end - size_at));
    writeBytes(path, file.substr(0, size_at) + std::to_string(claimed + 1) + file.substr(size_end));
    EXPECT_NE(refusal(path).find("claims " + std::to_string(claimed + 1) + " nodes"), std::string::npos)
        << refusal(path);
    // 2 MB of 0xff after a valid header: OctoMap's reader overflowed its stack on it.
    writeBytes(path, file.substr(0, data) + std::string(2 << 20, '\xff'));
    EXPECT_NE(refusal(path).find("truncated or damaged"), std::string::npos) << refusal(path);
    for (const std::string res : {"0", "-1", "inf", "nan"}) {
      const size_t res_at = file.find("res ") + 4, res_end = file.find('\n', res_at);
      writeBytes(path, file.substr(0, res_at) + res + file.substr(res_end));
      EXPECT_NE(refusal(path).find("resolution"), std::string::npos) << res << ": " << refusal(path);
    }
    const size_t id_at = file.find("id ") + 3, id_end = file.find('\n', id_at);
    writeBytes(path, file.substr(0, id_at) + "ColorOcTree" + file.substr(id_end));
    EXPECT_NE(refusal(path).find("holds a ColorOcTree"), std::string::npos) << refusal(path);
    std::remove(path.c_str());
  }
  const std::string text = tempPath("not_a_map.bt");
  writeBytes(text, std::string(50000, '\xff'));
  EXPECT_NE(refusal(text).find("no OctoMap header"), std::string::npos) << refusal(text);
  writeBytes(text, "# Octomap OcTree binary file\nid OcTree\nsize 1\nres 0.1\n");  // no "data" line
  EXPECT_NE(refusal(text).find("no \"data\" line"), std::string::npos) << refusal(text);
  writeBytes(text, "octomap?\nid OcTree\n");
  EXPECT_NE(refusal(text).find("does not start with"), std::string::npos) << refusal(text);
  std::remove(text.c_str());
  EXPECT_NE(refusal(tempPath("missing.ot")).find("No such file"), std::string::npos);
}
