// The learned descriptor's inference against FPFH on the same clusters, one core: a laser view of
// the housing at 0.7 mm voxels cut to 4 096 points (the size), and the matcher's 2 mm coarse
// cloud of the same view. Counters: the stages of compute() (structure: sampling, groups,
// frames; network: the forward pass) and the process's peak memory.
#include <benchmark/benchmark.h>
#include <sys/resource.h>

#include <string>

#include "cellsight/localization/descriptor_training.hpp"
#include "cellsight/localization/learned_descriptor.hpp"
#include "cellsight/localization/model_library.hpp"

namespace {

using namespace cellsight;

const std::string kRoot = CELLSIGHT_SOURCE_DIR;

ScanCloud cluster(double voxel, size_t cap) {
  LaserViewSetup s = randomLaserSetup(5);
  s.voxel = voxel;
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, 1, 0).normalized()).toRotationMatrix();
  ScanCloud c = laserView(loadValidMesh(kRoot + "/config/models/housing/mesh.ply"), T, s, 5).cloud;
  if (c.size() > cap) {
    c.points.resize(cap);
    c.normals.resize(cap);
    c.intensity.resize(cap);
  }
  return c;
}

const LearnedDescriptor& net() {
  static const LearnedDescriptor n = [] {
    LearnedDescriptor d = LearnedDescriptor::load(kRoot + "/config/descriptors/learned_k16.pt", 16);
    LearnedDescriptor::setThreads(1);
    return d;
  }();
  return n;
}

double peakMb() {
  rusage u{};
  getrusage(RUSAGE_SELF, &u);
  return u.ru_maxrss / 1024.0;
}

void learned(benchmark::State& state, double voxel, size_t cap) {
  const ScanCloud c = cluster(voxel, cap);
  DescriptorTiming t, sum;
  for (auto _ : state) {
    benchmark::DoNotOptimize(net().compute(c.points, c.normals, 1.0, &t));
    sum.structure_seconds += t.structure_seconds;
    sum.network_seconds += t.network_seconds;
  }
  state.counters["points"] = static_cast<double>(c.size());
  state.counters["structure_ms"] = 1e3 * sum.structure_seconds / static_cast<double>(state.iterations());
  state.counters["network_ms"] = 1e3 * sum.network_seconds / static_cast<double>(state.iterations());
  state.counters["peak_rss_mb"] = peakMb();
}

void fpfh(benchmark::State& state, double voxel, size_t cap) {
  const ScanCloud c = cluster(voxel, cap);
  for (auto _ : state) benchmark::DoNotOptimize(computeFpfh(c, 0.010));
  state.counters["points"] = static_cast<double>(c.size());
  state.counters["peak_rss_mb"] = peakMb();
}

}  // namespace

BENCHMARK_CAPTURE(learned, cluster_4096_points, 0.0007, 4096)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(fpfh, cluster_4096_points, 0.0007, 4096)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(learned, matcher_coarse_2mm, 0.002, 1000000)->Unit(benchmark::kMillisecond);
BENCHMARK_CAPTURE(fpfh, matcher_coarse_2mm, 0.002, 1000000)->Unit(benchmark::kMillisecond);
BENCHMARK_MAIN();
