// Named projector trajectories (config/trajectories.yaml): flange poses in the robot base frame.
#pragma once
#include <Eigen/Geometry>
#include <map>
#include <string>
#include <vector>

namespace cellsight {

/// Poses one trajectory may hold (a scan of 100 000 frames is hours of robot time).
constexpr int kMaxTrajectorySteps = 100000;

struct Trajectory {
  std::string name;
  std::string type;  ///< linear | rotation | poses
  std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>> poses;
};

/// Loads every trajectory of a file. Types:
///  linear:   start, end (poses), steps (≥ 2) — translation interpolated, rotation slerped;
///  rotation: start (pose), pivot [m], axis, angle_from, angle_to [rad], steps — the start pose
///            rotated about the pivot;
///  poses:    poses (list of poses).
std::map<std::string, Trajectory> loadTrajectories(const std::string& path);

/// One trajectory of a file; throws ConfigError naming the file's trajectories when it has no `name`.
Trajectory loadTrajectory(const std::string& path, const std::string& name);

/// Linear interpolation between two poses (slerp for the rotation), `steps` ≥ 2 poses.
Trajectory linearTrajectory(const Eigen::Isometry3d& start, const Eigen::Isometry3d& end, int steps);

}  // namespace cellsight
