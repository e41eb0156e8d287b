// libFuzzer target: mesh files as the scene loader and the real-data tools read them.
// The first byte picks the file name's extension (PLY is our reader; STL/OBJ go through assimp
// behind our checks); the rest is the file. Any exception derived from std::exception is a
// clean rejection; a crash, hang, leak or sanitizer report is a finding.
#include <cstddef>
#include <cstdint>
#include <exception>

#include "cellsight/common/mesh.hpp"
#include "fuzz_input.hpp"

extern "C" int LLVMFuzzerTestOneInput(const uint8_t* data, size_t size) {
  if (size < 1) return 0;
  static const char* const kNames[] = {"mesh.ply", "mesh.stl", "mesh.obj", "mesh.bin"};
  const std::string path = cellsight_fuzz::writeInput(data + 1, size - 1, kNames[data[0] % 4]);
  try {
    const cellsight::TriangleMesh mesh = cellsight::loadMesh(path);
    cellsight::checkMesh(mesh);
    cellsight::loadValidMesh(path, 0.001);
  } catch (const std::exception&) {
  }
  return 0;
}
