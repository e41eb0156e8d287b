// libFuzzer target: point-cloud files (PCD and PLY) as cellsight_locate and the localisation
// tools read them: our header and byte-count check first, then PCL's reader. The first byte
// picks the extension; the rest is the file.
#include <cstddef>
#include <cstdint>
#include <exception>

#include "cellsight/common/scan_cloud.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  const std::string path = cellsight_fuzz::writeInput(data + 1, size - 1, data[0] % 2 ? "cloud.ply" : "cloud.pcd");
  try {
    cellsight::loadCloud(path);
  } catch (const std::exception&) {
  }
  return 0;
}
