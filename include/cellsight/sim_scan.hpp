// A whole scan without ROS: render each pose with the simulated camera, extract the line,
// triangulate with a given calibration, accumulate in the base frame. Used by the accuracy tool,
// tests and benchmarks; the ROS nodes run the same extraction and triangulation per frame.
#pragma once
#include <Eigen/Geometry>
#include <memory>
#include <vector>

#include "cellsight/line_extraction.hpp"
#include "cellsight/renderer.hpp"
#include "cellsight/scan_cloud.hpp"
#include "cellsight/triangulation.hpp"

namespace cellsight {

/// The calibration the scanner uses (may differ from the simulator's truth).
struct ScannerCalibration {
  CameraIntrinsics intrinsics;
  Eigen::Isometry3d T_base_camera = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d T_flange_laser = Eigen::Isometry3d::Identity();
  double reference_z = 0.0;  ///< height of the support plane (table), base frame
  std::shared_ptr<const UndistortionMap> undistortion;  ///< built on first use when empty
  static ScannerCalibration fromScene(const Scene& scene);
};

struct SimScanStats {
  size_t frames = 0;
  LineExtractionStats line;  ///< summed over frames (background: last frame)
  double render_seconds = 0, process_seconds = 0;
};

/// Whether the laser line runs along image rows for a flange pose: the sheet's trace on the
/// support plane (z = reference_z) projected into the image. Decides the extraction direction.
bool lineAlongRows(const Eigen::Isometry3d& T_base_flange, const ScannerCalibration& cal);

/// One frame: line → profile points in the base frame (appended to `cloud`). The extraction
/// direction follows lineAlongRows() unless `auto_direction` is false.
void addProfile(const cv::Mat& image, const Eigen::Isometry3d& T_base_flange,
                const ScannerCalibration& cal, const LineExtractionConfig& line,
                const TriangulationConfig& tri, ScanCloud& cloud, LineExtractionStats* stats = nullptr,
                bool auto_direction = true);

ScanCloud simulateScan(const ScannerRenderer& renderer,
                       const std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>>& poses,
                       const ScannerCalibration& cal, const LineExtractionConfig& line,
                       const TriangulationConfig& tri, uint64_t seed, SimScanStats* stats = nullptr);

}  // namespace cellsight
