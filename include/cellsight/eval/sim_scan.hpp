// A whole scan without ROS: render each pose with the simulated camera, extract the line,
// triangulate with a given calibration, accumulate in the base frame. Used by the accuracy tool,
// tests and benchmarks; the ROS nodes run the same extraction and triangulation per frame.
#pragma once
#include <Eigen/Geometry>
#include <memory>
#include <string>
#include <vector>

#include "cellsight/scanner/accuracy.hpp"
#include "cellsight/scanner/line_extraction.hpp"
#include "cellsight/sim/renderer.hpp"
#include "cellsight/sim/robot_model.hpp"
#include "cellsight/common/scan_cloud.hpp"
#include "cellsight/scanner/triangulation.hpp"

namespace cellsight {

/// The calibration the scanner uses (may differ from the simulator's truth).
struct ScannerCalibration {
  CameraIntrinsics intrinsics;
  Eigen::Isometry3d T_base_camera = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d T_flange_laser = Eigen::Isometry3d::Identity();
  std::shared_ptr<const UndistortionMap> undistortion;  ///< built on first use when empty
  static ScannerCalibration fromScene(const Scene& scene);
  /// From a calibration folder (camera_info YAML + transform YAMLs, as calibration_publisher
  /// loads it). Throws ConfigError naming what is missing.
  static ScannerCalibration fromFolder(const std::string& dir, const std::string& camera_frame = "scanner_camera_optical",
                                       const std::string& laser_frame = "laser",
                                       const std::string& camera_name = "scanner_camera");
};

struct SimScanStats {
  size_t frames = 0;
  LineExtractionStats line;  ///< summed over frames (background: last frame)
  double render_seconds = 0, process_seconds = 0;
};

/// Whether the laser line runs along image rows: the sheet's trace on a surface facing the
/// camera runs along n × z (camera frame), i.e. along u when |n_y| ≥ |n_x|. Decides the
/// extraction direction (the same rule in the ROS node and in-process).
bool lineAlongRows(const Plane& plane_camera);

/// One frame: line → profile points in the base frame (appended to `cloud`). The extraction
/// direction follows lineAlongRows() unless `auto_direction` is false.
void addProfile(const cv::Mat& image, const Eigen::Isometry3d& T_base_flange,
                const ScannerCalibration& cal, const LineExtractionConfig& line,
                const TriangulationConfig& tri, ScanCloud& cloud, LineExtractionStats* stats = nullptr,
                bool auto_direction = true);

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
