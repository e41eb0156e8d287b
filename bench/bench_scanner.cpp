// Speed of the scanner's per-frame work on one core: line extraction + triangulation of one
// 1920×1080 mono8 frame of the demo scene, beside one plain pass over the same pixels (the
// memory-bound floor) and a peer: OpenCV's per-column maximum (cv::reduce) + cv::undistortPoints.
#include <benchmark/benchmark.h>

#include <opencv2/calib3d.hpp>
#include <opencv2/core.hpp>

#include "cellsight/sim/renderer.hpp"
#include "cellsight/eval/sim_scan.hpp"
#include "cellsight/common/trajectory.hpp"

namespace {

struct Data {
  cellsight::ScannerCalibration cal;
  std::vector<cv::Mat> frames;
  std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>> poses;
  static Data& get() {
    static Data d = [] {
      Data x;
      const std::string root = CELLSIGHT_SOURCE_DIR;
      const cellsight::Scene scene = cellsight::loadScene(root + "/config/scenes/demo.yaml");
      auto geometry = std::make_shared<cellsight::CellGeometry>(scene);
      cellsight::ScannerRenderer renderer(geometry);
      x.cal = cellsight::scannerCalibrationOf(scene);
      const auto sweep = cellsight::loadTrajectories(root + "/config/trajectories.yaml").at("demo_sweep");
      for (size_t i = 0; i < sweep.poses.size(); i += 15) {  // 10 frames across the sweep
        x.frames.push_back(renderer.render(sweep.poses[i], i));
        x.poses.push_back(sweep.poses[i]);
      }
      return x;
    }();
    return d;
  }
};

void BM_ExtractAndTriangulate(benchmark::State& state) {
  Data& d = Data::get();
  cellsight::LineExtractionConfig line;
  cellsight::TriangulationConfig tri;
  size_t i = 0, points = 0;
  for (auto _ : state) {
    cellsight::ScanCloud cloud;
    cellsight::addProfile(d.frames[i % d.frames.size()], d.poses[i % d.poses.size()], d.cal, line, tri, cloud);
    points += cloud.size();
    benchmark::DoNotOptimize(cloud.points.data());
    ++i;
  }
  state.counters["points/frame"] = static_cast<double>(points) / static_cast<double>(i);
  state.SetLabel("cellsight: ridge + linking + smoothing along the line + LUT undistortion");
}
BENCHMARK(BM_ExtractAndTriangulate)->Unit(benchmark::kMillisecond);

void extractOnly(benchmark::State& state, cellsight::LineExtractionConfig::Estimator estimator) {
  Data& d = Data::get();
  cellsight::LineExtractionConfig line;
  line.estimator = estimator;
  size_t i = 0, points = 0;
  for (auto _ : state) {
    auto pts = cellsight::extractLine(d.frames[i++ % d.frames.size()], line);
    points += pts.size();
    benchmark::DoNotOptimize(pts.data());
  }
  state.counters["points/frame"] = static_cast<double>(points) / static_cast<double>(i);
  state.SetLabel(cellsight::LineExtractionConfig::estimatorName(estimator));
}
/// The default: orientation-free ridge centres, linked and smoothed.
void BM_ExtractOnly(benchmark::State& state) { extractOnly(state, cellsight::LineExtractionConfig::Estimator::kRidge); }
BENCHMARK(BM_ExtractOnly)->Unit(benchmark::kMillisecond);
/// The column method (one centre per column, centroid + smoothing) on the same frames.
void BM_ExtractColumnsCentroid(benchmark::State& state) {
  extractOnly(state, cellsight::LineExtractionConfig::Estimator::kCentroid);
}
BENCHMARK(BM_ExtractColumnsCentroid)->Unit(benchmark::kMillisecond);

void BM_PeerOpenCvColumnMaxUndistort(benchmark::State& state) {
  // What a user would glue together from OpenCV: per-column maximum row, then undistortPoints.
  Data& d = Data::get();
  const auto& K = d.cal.intrinsics;
  const cv::Matx33d Km(K.fx, 0, K.cx, 0, K.fy, K.cy, 0, 0, 1);
  const std::vector<double> dist(K.dist.begin(), K.dist.end());
  size_t i = 0;
  for (auto _ : state) {
    const cv::Mat& img = d.frames[i++ % d.frames.size()];
    cv::Mat t = img.t();  // columns → rows
    std::vector<cv::Point2f> px;
    px.reserve(static_cast<size_t>(img.cols));
    for (int u = 0; u < t.rows; ++u) {
      cv::Point maxLoc;
      double mx;
      cv::minMaxLoc(t.row(u), nullptr, &mx, nullptr, &maxLoc);
      if (mx > 40) px.emplace_back(static_cast<float>(u), static_cast<float>(maxLoc.x));
    }
    std::vector<cv::Point2f> und;
    if (!px.empty()) cv::undistortPoints(px, und, Km, dist);
    benchmark::DoNotOptimize(und.data());
  }
  state.SetLabel("peer: cv::minMaxLoc per column (integer peak) + cv::undistortPoints");
}
BENCHMARK(BM_PeerOpenCvColumnMaxUndistort)->Unit(benchmark::kMillisecond);

void BM_PlainPassFloor(benchmark::State& state) {
  // One read of every pixel (sum of bytes): the memory-bound floor for any per-frame method.
  Data& d = Data::get();
  size_t i = 0;
  for (auto _ : state) {
    const cv::Mat& img = d.frames[i++ % d.frames.size()];
    uint64_t sum = 0;
    for (int v = 0; v < img.rows; ++v) {
      const uint8_t* r = img.ptr<uint8_t>(v);
      for (int u = 0; u < img.cols; ++u) sum += r[u];
    }
    benchmark::DoNotOptimize(sum);
  }
  state.SetLabel("one pass over the 2 MP");
}
BENCHMARK(BM_PlainPassFloor)->Unit(benchmark::kMillisecond);

}  // namespace

BENCHMARK_MAIN();
