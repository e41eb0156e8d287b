// A whole scan without ROS: render each pose with the simulated camera and run the scanner's
// per-frame profile (scanner/scan_pipeline.hpp, as the triangulation node does) with a given
// calibration. Used by the accuracy tool, the evaluation, tests and benchmarks.
#pragma once
#include <Eigen/Geometry>
#include <memory>
#include <string>
#include <vector>

#include "cellsight/scanner/accuracy.hpp"
#include "cellsight/scanner/line_extraction.hpp"
#include "cellsight/scanner/scan_pipeline.hpp"
#include "cellsight/sim/renderer.hpp"
#include "cellsight/sim/robot_model.hpp"
#include "cellsight/common/scan_cloud.hpp"
#include "cellsight/scanner/triangulation.hpp"

namespace cellsight {

/// The simulator's true scanner calibration (the scene's camera, intrinsics and laser mount).
ScannerCalibration scannerCalibrationOf(const Scene& scene);

struct SimScanStats {
  size_t frames = 0;
  LineExtractionStats line;  ///< summed over frames (background: last frame)
  double render_seconds = 0, process_seconds = 0;
};

/// Scans along `poses` (the poses the robot is told and reports; with `robot`, the frames are
/// rendered where its flange really goes) and triangulates with `cal`.
ScanCloud simulateScan(const ScannerRenderer& renderer,
                       const std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>>& poses,
                       const ScannerCalibration& cal, const LineExtractionConfig& line,
                       const TriangulationConfig& tri, uint64_t seed, SimScanStats* stats = nullptr,
                       const RobotErrorModel* robot = nullptr);

/// Flange poses sweeping the light line across `target` (base frame) with the flange turned by
/// `yaw` about the vertical from the robot's home orientation: the sheet's horizontal normal
/// sets the sweep direction; ±half_span around the pose whose central beam hits the target
/// height at the target, in `step` increments, flange at `flange_height`.
std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>> sweepAcross(
    const Scene& scene, const Eigen::Vector3d& target, double yaw, double half_span, double step,
    double flange_height);

struct SphereAcceptance {
  std::vector<SphereFit> fits;  ///< one per projector orientation
  double mpe_p = 0;             ///< first orientation (one robot motion), metres
  double mpe_p_worst = 0;       ///< worst of the K
  double mpe_al = 0;            ///< diameter of the smallest sphere holding the K centres
  Eigen::Vector3d true_center = Eigen::Vector3d::Zero();
  double true_radius = 0;
  std::vector<size_t> frames;
};

/// MPE_P and MPE_AL on a reference sphere object of the scene (K orientations 360°/K apart).
SphereAcceptance sphereAcceptance(const ScannerRenderer& renderer, const SceneObject& sphere,
                                  const ScannerCalibration& cal, const LineExtractionConfig& line,
                                  const TriangulationConfig& tri, int K, double step, bool filter,
                                  const RobotErrorModel* robot = nullptr);

}  // namespace cellsight
