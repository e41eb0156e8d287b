// The scanner's pipeline, the one implementation the triangulation node, the tools, the benches
// and the in-process evaluation run: a frame's profile (line → triangulation → base frame) and
// a scan's finish (workspace crop, outlier filter, normals).
#pragma once
#include <Eigen/Geometry>
#include <memory>
#include <opencv2/core.hpp>
#include <string>

#include "cellsight/common/camera_model.hpp"
#include "cellsight/common/plane.hpp"
#include "cellsight/common/scan_cloud.hpp"
#include "cellsight/scanner/line_extraction.hpp"
#include "cellsight/scanner/scanner_config.hpp"
#include "cellsight/scanner/triangulation.hpp"

namespace cellsight {

/// The calibration the scanner triangulates with (a user's calibration folder, or in the
/// simulator its truth: scannerCalibrationOf() in eval/sim_scan.hpp).
struct ScannerCalibration {
  CameraIntrinsics intrinsics;
  Eigen::Isometry3d T_base_camera = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d T_flange_laser = Eigen::Isometry3d::Identity();
  std::shared_ptr<const UndistortionMap> undistortion;  ///< of `intrinsics`; set by the factories
  /// From a calibration folder (camera_info YAML + transform YAMLs, as calibration_publisher
  /// loads it). Throws ConfigError naming what is missing.
  static ScannerCalibration fromFolder(const std::string& dir, const std::string& camera_frame = "scanner_camera_optical",
                                       const std::string& laser_frame = "laser",
                                       const std::string& camera_name = "scanner_camera");
};

/// Whether the laser line runs along image rows: the sheet's trace on a surface facing the
/// camera runs along n × z (camera frame), i.e. along u when |n_y| ≥ |n_x|. Decides the
/// extraction direction.
bool lineAlongRows(const Plane& plane_camera);

/// One frame's profile appended to `cloud` (base frame): the line found in `image` (searched
/// across the sheet's trace, lineAlongRows), triangulated on the sheet `plane_camera` (camera
/// frame) and moved by `T_base_camera`. Adds the extraction's counts to `stats`. Returns the
/// points added.
size_t addFrameProfile(const cv::Mat& image, const Plane& plane_camera, const Eigen::Isometry3d& T_base_camera,
                       const UndistortionMap& undistortion, LineExtractionConfig line, const TriangulationConfig& tri,
                       ScanCloud& cloud, LineExtractionStats* stats = nullptr);

/// The same for a frame taken with the flange at `T_base_flange` (the robot's report): the sheet
/// from the calibration's flange → laser transform. Throws std::invalid_argument when `cal` has
/// no undistortion map.
size_t addProfile(const cv::Mat& image, const Eigen::Isometry3d& T_base_flange, const ScannerCalibration& cal,
                  const LineExtractionConfig& line, const TriangulationConfig& tri, ScanCloud& cloud,
                  LineExtractionStats* stats = nullptr);

/// A scan's finish (config/scanner.yaml): the workspace crop, the statistical outlier filter
/// (outlier_k > 0) and normals oriented towards `viewpoint`, the scanner camera (normal_k > 0).
ScanCloud finishScan(const ScanCloud& raw, const ScannerSettings& settings, const Eigen::Vector3f& viewpoint);

}  // namespace cellsight
