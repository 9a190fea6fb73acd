#pragma once
/// @file
/// Map files: atomic, synced writes of an octomap::OcTree.

#include <octomap/OcTree.h>

#include <functional>
#include <ostream>
#include <string>

namespace stereo_occupancy {

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
