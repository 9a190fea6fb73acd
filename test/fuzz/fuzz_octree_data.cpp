// libFuzzer target: arbitrary bytes as a map file (.bt / .ot) or as the tree
// data of a tile row, the two ways a tree reaches OctoMap's readers from
// disk. Nothing may crash or recurse without bound; what checkOcTreeData()
// accepts, OctoMap must read to the very tree it counted.

#include <unistd.h>

#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <stdexcept>
#include <string>

#include "stereo_occupancy/octomap_io.h"

namespace so = stereo_occupancy;

namespace {

/// Checks @p bytes as tree data of @p encoding; an accepted stream must read to the counted tree.
void fuzzData(const std::string& bytes, so::OcTreeEncoding encoding) {
  so::OcTreeDataShape shape;
  try {
    shape = so::checkOcTreeData(bytes.data(), bytes.size(), encoding);
  } catch (const std::runtime_error&) {
    return;  // refused: the reader never sees it
  }
  const auto tree = so::readOcTreeData(bytes, encoding, 0.1);  // must not throw: the walk accepted it
  if (tree->size() != shape.nodes || tree->getNumLeafNodes() != shape.leaves) std::abort();
}

/// The bytes as a whole map file, through readOcTreeFile.
void fuzzFile(const std::string& bytes) {
  static const std::string path = "/tmp/fuzz_octree_data_" + std::to_string(::getpid()) + ".ot";
  std::ofstream(path, std::ios::binary | std::ios::trunc) << bytes;
  try {
    const auto tree = so::readOcTreeFile(path);
    if (!(tree->getResolution() > 0.0)) std::abort();
  } catch (const std::runtime_error&) {
  }
}

}  // namespace

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size == 0) return 0;
  const std::string bytes(reinterpret_cast<const char*>(data) + 1, size - 1);
  switch (data[0] % 3) {
    case 0:
      fuzzData(bytes, so::OcTreeEncoding::kFull);
      break;
    case 1:
      fuzzData(bytes, so::OcTreeEncoding::kBinary);
      break;
    default: {
      // A header OctoMap writes, then the fuzzer's data: the walk sees past it quickly.
      const bool binary = data[0] % 2 == 0;
      fuzzFile(std::string(binary ? "# Octomap OcTree binary file\n" : "# Octomap OcTree file\n") + "id OcTree\nsize " +
               std::to_string(size % 1000) + "\nres 0.1\ndata\n" + bytes);
      fuzzFile(bytes);
      break;
    }
  }
  return 0;
}
