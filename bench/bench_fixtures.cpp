// Speed of the QR fixture chain on one core: one 1280×960 fixture-camera frame of the demo scene
// (fixtures A and B with one code each, C with three), 10 noise draws:
//   DecodeAndPose      decoding (zbar), corner refinement, poses, user frames: what the node does
//   DecodeOnly         the same without the poses
//   ZbarAlone          zbar's decoding on the frame, nothing else (the reference)
//   WechatAlone        OpenCV contrib's wechat_qrcode on the frame (its traditional detector)
#include <benchmark/benchmark.h>

#include <opencv2/core.hpp>

#include "cellsight/fixtures/fixture_adjustment.hpp"
#include "cellsight/sim/renderer.hpp"

namespace {

struct Data {
  cellsight::Scene scene;
  cellsight::FixtureRegistry registry;
  std::vector<cv::Mat> frames;
  static Data& get() {
    static Data d = [] {
      cv::setNumThreads(1);
      Data x;
      const std::string root = CELLSIGHT_SOURCE_DIR;
      x.scene = cellsight::loadScene(root + "/config/scenes/demo.yaml");
      x.registry = cellsight::loadFixtureRegistry(root + "/config/fixtures.yaml");
      cellsight::FixtureRenderer renderer(std::make_shared<cellsight::CellGeometry>(x.scene));
      for (uint64_t k = 0; k < 10; ++k) x.frames.push_back(renderer.render(1000 + k));
      return x;
    }();
    return d;
  }
};

cellsight::QrDetectorConfig config(const Data& d) {
  cellsight::QrDetectorConfig c;
  c.expected_codes = 0;
  for (const auto& f : d.registry.fixtures) c.expected_codes += static_cast<int>(f.codes.size());
  return c;
}

void BM_DecodeAndPose(benchmark::State& state) {
  Data& d = Data::get();
  const cellsight::QrDetector detector(config(d));
  const auto& cam = d.scene.fixture_camera;
  size_t i = 0, fixtures = 0;
  for (auto _ : state) {
    const auto r = cellsight::adjustFixtures(detector.detect(d.frames[i++ % d.frames.size()], &cam.intrinsics),
                                             d.registry, cam.intrinsics, cam.T_base_camera);
    fixtures += r.fixtures.size();
  }
  state.counters["fixtures_per_frame"] = static_cast<double>(fixtures) / static_cast<double>(state.iterations());
}
BENCHMARK(BM_DecodeAndPose)->Unit(benchmark::kMillisecond);

void BM_DecodeOnly(benchmark::State& state) {
  Data& d = Data::get();
  const cellsight::QrDetector detector(config(d));
  size_t i = 0, codes = 0;
  for (auto _ : state) codes += detector.detect(d.frames[i++ % d.frames.size()], &d.scene.fixture_camera.intrinsics).size();
  state.counters["codes_per_frame"] = static_cast<double>(codes) / static_cast<double>(state.iterations());
}
BENCHMARK(BM_DecodeOnly)->Unit(benchmark::kMillisecond);

void BM_ZbarAlone(benchmark::State& state) {
  Data& d = Data::get();
  const cellsight::QrDetector detector;
  size_t i = 0, codes = 0;
  for (auto _ : state) codes += detector.detectZbar(d.frames[i++ % d.frames.size()]).size();
  state.counters["codes_per_frame"] = static_cast<double>(codes) / static_cast<double>(state.iterations());
}
BENCHMARK(BM_ZbarAlone)->Unit(benchmark::kMillisecond);

void BM_WechatAlone(benchmark::State& state) {
  Data& d = Data::get();
  const cellsight::QrDetector detector;
  size_t i = 0, codes = 0;
  for (auto _ : state) codes += detector.detectWechat(d.frames[i++ % d.frames.size()]).size();
  state.counters["codes_per_frame"] = static_cast<double>(codes) / static_cast<double>(state.iterations());
}
BENCHMARK(BM_WechatAlone)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
