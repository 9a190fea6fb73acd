#pragma once
/// @file
/// Map files and OctoMap data: checked reads, atomic and synced writes.
///
/// OctoMap 1.9.7's readers trust their input: they recurse without a depth
/// limit and read on past the end of the data, so a damaged or hostile file
/// or tile row overflows the stack or allocates without bound. Every tree the
/// package reads from a file or a database goes through checkOcTreeData()
/// first, which walks the stream without building anything.

#include <octomap/OcTree.h>

#include <cstddef>
#include <functional>
#include <memory>
#include <ostream>
#include <string>

namespace stereo_occupancy {

/// The two encodings of an OctoMap tree's nodes.
enum class OcTreeEncoding {
  kFull,    ///< OcTree::writeData (.ot): every node's float log-odds and its child bits
  kBinary,  ///< OcTree::writeBinaryData (.bt): two bits a child, occupied / free / inner
};

/// What checkOcTreeData() found in a stream.
struct OcTreeDataShape {
  size_t nodes = 0;   ///< nodes of the tree the stream encodes, the root included (OcTree::size())
  size_t leaves = 0;  ///< of which leaves
};

/// Walks the tree that @p data (@p size bytes) encodes, in pre-order, without
/// building it: the stream must end exactly with the tree, no node may lie
/// deeper than OctoMap's 16 levels, and every log-odds (kFull) must be finite.
/// Costs O(size) time and no memory beyond a 17-level stack. An empty stream
/// is the empty tree.
/// @throws std::runtime_error saying what is wrong and at which byte.
OcTreeDataShape checkOcTreeData(const char* data, size_t size, OcTreeEncoding encoding);

/// Reads @p bytes (checked by checkOcTreeData) into a new tree of
/// @p resolution_m cells. @throws std::runtime_error if they are not one whole tree.
std::unique_ptr<octomap::OcTree> readOcTreeData(const std::string& bytes, OcTreeEncoding encoding, double resolution_m);

/// Reads a map file of an OcTree, .bt or .ot (told by its first line, as
/// OctoMap writes it), checking it before OctoMap's reader sees it: its
/// header (id OcTree, a finite positive resolution, a node count), then its
/// data against that count (a truncated or padded file is refused). Memory:
/// the file's bytes and the tree it holds.
/// @throws std::runtime_error naming the file and what is wrong.
std::unique_ptr<octomap::OcTree> readOcTreeFile(const std::string& path);

/// Writes @p tree to @p path: ".ot" keeps the log-odds (octomap::AbstractOcTree::write),
/// ".bt" keeps occupied / free only (writeBinary). Atomic: written to a
/// temporary file in the same directory (path + ".tmp" + the process id), then
/// renamed into place; first removes the temporaries that killed writers left
/// (removeStaleTemporaries).
/// @throws std::runtime_error.
void writeOcTree(const octomap::OcTree& tree, const std::string& path);

/// writeOcTree's atomic write for any content: @p write fills the stream
/// (false or an exception: failed). @throws std::runtime_error naming the file and the reason.
void writeFileAtomically(const std::string& path, const std::function<bool(std::ostream&)>& write);

/// Removes the files path + ".tmp" + PID in @p path's directory whose process
/// PID no longer exists (left by a writer killed during writeOcTree).
/// @return how many were removed.
int removeStaleTemporaries(const std::string& path);

}  // namespace stereo_occupancy
