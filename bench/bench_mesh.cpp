// Mesh reading (loadMesh: own PLY reader, assimp for every other format) on the shipped sphere
// model (binary PLY) and a 330 k-triangle sphere written as binary PLY, binary STL and OBJ. PLY
// stays on the own reader because Debian's assimp misreads binary PLY face lists.
#include <benchmark/benchmark.h>
#include <unistd.h>

#include <cstdio>
#include <cstring>
#include <fstream>
#include <string>

#include "cellsight/common/mesh.hpp"

namespace {

struct Files {
  std::string shipped = std::string(CELLSIGHT_SOURCE_DIR) + "/config/models/sphere25/mesh.ply";
  std::string big_ply = "/tmp/cellsight_bench_mesh_" + std::to_string(::getpid()) + ".ply";
  std::string big_stl = "/tmp/cellsight_bench_mesh_" + std::to_string(::getpid()) + ".stl";
  std::string big_obj = "/tmp/cellsight_bench_mesh_" + std::to_string(::getpid()) + ".obj";
  size_t big_faces = 0;
  static Files& get() {
    static Files f = [] {
      Files x;
      const cellsight::TriangleMesh m = cellsight::makeSphere(0.05, 7);
      x.big_faces = m.faces.size();
      cellsight::saveMeshPly(x.big_ply, m);
      std::ofstream out(x.big_stl, std::ios::binary);
      char header[80] = "cellsight bench";
      out.write(header, 80);
      const uint32_t n = static_cast<uint32_t>(m.faces.size());
      out.write(reinterpret_cast<const char*>(&n), 4);
      for (const auto& f : m.faces) {
        const Eigen::Vector3f a = m.vertices[f[0]], b = m.vertices[f[1]], c = m.vertices[f[2]];
        const Eigen::Vector3f nrm = (b - a).cross(c - a).normalized();
        out.write(reinterpret_cast<const char*>(nrm.data()), 12);
        for (const auto* v : {&a, &b, &c}) out.write(reinterpret_cast<const char*>(v->data()), 12);
        const uint16_t attr = 0;
        out.write(reinterpret_cast<const char*>(&attr), 2);
      }
      std::ofstream obj(x.big_obj);
      for (const auto& v : m.vertices) obj << "v " << v.x() << " " << v.y() << " " << v.z() << "\n";
      for (const auto& f : m.faces) obj << "f " << f[0] + 1 << " " << f[1] + 1 << " " << f[2] + 1 << "\n";
      return x;
    }();
    return f;
  }
  ~Files() {
    std::remove(big_ply.c_str());
    std::remove(big_stl.c_str());
    std::remove(big_obj.c_str());
  }
};

template <bool kAssimp>
void load(benchmark::State& state, const std::string& path) {
  size_t faces = 0;
  for (auto _ : state) {
    const cellsight::TriangleMesh m = kAssimp ? cellsight::loadMeshWithAssimp(path) : cellsight::loadMesh(path);
    faces = m.faces.size();
    benchmark::DoNotOptimize(m.vertices.data());
  }
  state.counters["faces"] = static_cast<double>(faces);
}

void BM_ShippedPly_Own(benchmark::State& s) { load<false>(s, Files::get().shipped); }
void BM_BigPly_Own(benchmark::State& s) { load<false>(s, Files::get().big_ply); }
void BM_BigStl_Assimp(benchmark::State& s) { load<true>(s, Files::get().big_stl); }
void BM_BigObj_Assimp(benchmark::State& s) { load<true>(s, Files::get().big_obj); }
BENCHMARK(BM_ShippedPly_Own)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_BigPly_Own)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_BigStl_Assimp)->Unit(benchmark::kMillisecond);
BENCHMARK(BM_BigObj_Assimp)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
