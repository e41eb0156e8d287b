// Speed of the simulated scanner camera: one 1920×1080 frame of the demo scene on one core,
// beside a plain pass writing the same pixels (the memory-bound floor of any renderer).
#include <benchmark/benchmark.h>

#include <opencv2/core.hpp>

#include "cellsight/sim/renderer.hpp"
#include "cellsight/common/trajectory.hpp"

namespace {

struct Fixture {
  std::shared_ptr<cellsight::CellGeometry> geometry;
  std::unique_ptr<cellsight::ScannerRenderer> renderer;
  cellsight::Trajectory sweep;
  static Fixture& get() {
    static Fixture f = [] {
      Fixture x;
      const std::string root = CELLSIGHT_SOURCE_DIR;
      x.geometry = std::make_shared<cellsight::CellGeometry>(
          cellsight::loadScene(root + "/config/scenes/demo.yaml"));
      x.renderer = std::make_unique<cellsight::ScannerRenderer>(x.geometry);
      x.sweep = cellsight::loadTrajectories(root + "/config/trajectories.yaml").at("demo_sweep");
      return x;
    }();
    return f;
  }
};

void BM_RenderScannerFrame(benchmark::State& state) {
  Fixture& f = Fixture::get();
  size_t i = 0;
  for (auto _ : state) {
    cv::Mat img = f.renderer->render(f.sweep.poses[i % f.sweep.poses.size()], i);
    benchmark::DoNotOptimize(img.data);
    ++i;
  }
  state.SetLabel("1920x1080 mono8, demo scene, noise on");
}
BENCHMARK(BM_RenderScannerFrame)->Unit(benchmark::kMillisecond);

void BM_RenderLaserOnlyNoNoise(benchmark::State& state) {
  Fixture& f = Fixture::get();
  size_t i = 0;
  for (auto _ : state) {
    cv::Mat img = f.renderer->renderLaserOnly(f.sweep.poses[i % f.sweep.poses.size()]);
    benchmark::DoNotOptimize(img.data);
    ++i;
  }
}
BENCHMARK(BM_RenderLaserOnlyNoNoise)->Unit(benchmark::kMillisecond);

void BM_PlainPixelPassFloor(benchmark::State& state) {
  // One read of a float per pixel and one 8-bit write: the floor of a per-pixel renderer.
  cv::Mat src(1080, 1920, CV_32F, cv::Scalar(12.5f)), dst(1080, 1920, CV_8UC1);
  for (auto _ : state) {
    src.convertTo(dst, CV_8U);
    benchmark::DoNotOptimize(dst.data);
  }
}
BENCHMARK(BM_PlainPixelPassFloor)->Unit(benchmark::kMillisecond);

void BM_SceneSetup(benchmark::State& state) {
  Fixture& f = Fixture::get();
  for (auto _ : state) {
    cellsight::ScannerRenderer r(f.geometry);
    benchmark::DoNotOptimize(&r);
  }
  state.SetLabel("primary rays for all 2 MP, once per scene");
}
BENCHMARK(BM_SceneSetup)->Unit(benchmark::kMillisecond)->Iterations(2);

}  // namespace

BENCHMARK_MAIN();
