// Calibrated transforms as YAML files: one file per calibration, loaded by calibration_publisher.
#pragma once
#include <Eigen/Geometry>
#include <string>
#include <vector>

namespace cellsight {

/// One calibrated rigid transform `T_parent_child` (maps child coordinates into parent).
struct TransformCalibration {
  std::string parent_frame;
  std::string child_frame;
  Eigen::Isometry3d T_parent_child = Eigen::Isometry3d::Identity();
  double residual_rms = 0.0;  ///< method-specific residual (metres or pixels, see `method`)
  std::string method;         ///< how it was obtained, e.g. "simulator ground truth"
  std::string date;           ///< ISO 8601
};

TransformCalibration loadTransformCalibration(const std::string& path);
std::string transformCalibrationYaml(const TransformCalibration& cal);
/// Writes atomically after checking the text as loadTransformCalibration would: one it would
/// refuse (e.g. a child frame equal to its parent) throws ConfigError, the old file kept.
void saveTransformCalibration(const std::string& path, const TransformCalibration& cal);

/// What a calibration folder holds: every *.yaml is either a transform (has `parent_frame`)
/// or camera intrinsics (has `camera_matrix`). Throws ConfigError on the first bad file, and on
/// two files calibrating the same child frame (tf would keep one of them silently).
struct CalibrationSet {
  std::vector<std::pair<std::string, TransformCalibration>> transforms;  ///< (file, value)
  std::vector<std::string> camera_files;
};
CalibrationSet loadCalibrationFolder(const std::string& folder);

/// Current UTC time as ISO 8601.
std::string isoDateNow();

}  // namespace cellsight
