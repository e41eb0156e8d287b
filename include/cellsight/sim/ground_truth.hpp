// What the simulator knows for certain, written for evaluation: object and fixture poses, the
// true calibrations (in the same formats calibration_publisher loads), per-frame light planes.
#pragma once
#include <Eigen/Geometry>
#include <string>

#include "cellsight/sim/renderer.hpp"
#include "cellsight/sim/scene.hpp"

namespace cellsight {

/// Writes `<dir>/scene_truth.json` and the true calibration files under `<dir>/calibration/`:
/// scanner_camera.yaml, fixture_camera.yaml (ROS camera_info), scanner_camera_pose.yaml,
/// fixture_camera_pose.yaml and laser.yaml (transforms). Creates the folders. Atomic per file.
void writeSceneTruth(const Scene& scene, const std::string& dir);

/// JSON of the scene's ground truth (objects, fixtures, workspace, frames).
std::string sceneTruthJson(const Scene& scene);

/// One line of frames_truth.jsonl: frame index, stamp, flange pose, light plane (camera frame).
std::string frameTruthJsonLine(int index, int64_t stamp_ns, const Eigen::Isometry3d& T_base_flange,
                               const Plane& plane_camera);

}  // namespace cellsight
