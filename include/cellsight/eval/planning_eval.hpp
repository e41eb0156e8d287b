// The full cell cycle in-process, against the simulator's truth: scan the cell (the calibration
// the user's cell made, or the truth), cluster, locate, plan every part of the assembly and
// execute the plans with the simulated robot as built (its kinematic error and repeatability);
// the gripper carries the true part, so where it ends is compared with where the assembly wants
// it (true base part · T_0i). The thesis's grasp-accuracy test, repeated per cycle with fresh
// image noise and robot scatter. The pipeline never sees the truth; only the scoring does.
#pragma once
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "cellsight/planning/grasp_planner.hpp"
#include "cellsight/sim/robot_model.hpp"

namespace cellsight {

struct PlanningEvalConfig {
  std::string root = ".";                        ///< the package folder (config/, urdf/)
  std::string scene = "config/scenes/demo.yaml"; ///< relative to root unless absolute
  std::string calibration;                       ///< calibration folder; empty: the simulator's truth
  std::string trajectory = "demo_sweep";
  /// a second scan along this trajectory refines the located parts (ModelMatcher::refine; empty: none)
  std::string refine_trajectory;
  std::string dump_scans;  ///< write every cycle's finished scan here as scan_<seed>.ply (empty: none)
  MotionPlannerConfig motion;
  GripperConfig gripper;
  // error budget rows (diagnostics, never the system's figure)
  bool exact_robot = false;  ///< the plans are executed by a robot without kinematic error or scatter
  bool true_poses = false;   ///< the planner is given the true part poses instead of the located ones
};

struct PlacementResult {
  std::string name, model, status, reason;
  std::string truth;          ///< the scene object the detection was matched to ("" for none)
  bool executed = false;
  double place_t_err_mm = 0, place_r_err_deg = 0;  ///< placed vs the assembly target (truth), symmetry-aware
  Eigen::Vector3d offset_mm = Eigen::Vector3d::Zero();  ///< placed − target centroid, base frame
  Eigen::Vector3d rotation_deg = Eigen::Vector3d::Zero();  ///< rotation vector target → placed (symmetry removed), base frame
  double plan_seconds = 0, motion_seconds = 0;
  bool sampled = false;       ///< OMPL was needed for a joint segment
  int candidates_tried = 0;
};

/// A located part against its truth: the error (symmetry-aware) and its components
/// (placementDeviation of the located pose against the true one, base frame).
struct LocateError {
  std::string model;
  double t_err_mm = 0, r_err_deg = 0;
  Eigen::Vector3d offset_mm = Eigen::Vector3d::Zero(), rotation_deg = Eigen::Vector3d::Zero();
};

struct CycleReport {
  uint64_t seed = 0;
  size_t scan_points = 0, located = 0;
  double scan_seconds = 0, locate_seconds = 0, plan_seconds = 0, world_seconds = 0;
  double refine_scan_seconds = 0, refine_seconds = 0;  ///< the second scan and the refinement (0: none)
  size_t refined = 0;                                  ///< parts the second scan moved
  std::vector<std::string> refine_warnings;
  size_t voxels = 0;
  std::vector<PlacementResult> placements;
  /// each located part against its truth, by instance name (scoring only)
  std::map<std::string, LocateError> locate_errors;
};

/// Where the true part ends when `plan` is executed by `robot` (the controller holds the plan's
/// joints at the grasp and at the release, the arm as built takes the flange where they lead; the
/// part rides rigidly in the jaws from the grasp on). Move numbers `move` and `move + 1` draw the
/// repeatability.
/// Placed vs target: centroid offset (m) and rotation vector (rad, base frame) with the part's
/// symmetry taken out (the equivalent target nearest the placed pose; for an axial part the
/// turn about its axis is dropped).
void placementDeviation(const ModelInfo& info, const Eigen::Vector3d& centroid, const Eigen::Isometry3d& placed,
                        const Eigen::Isometry3d& target, Eigen::Vector3d* offset, Eigen::Vector3d* rotation);

Eigen::Isometry3d simulatePlacement(const ArmModel& arm, const RobotErrorModel& robot, const PartPlan& plan,
                                    const Eigen::Isometry3d& T_base_part_true, uint64_t move);

class PlanningEvaluation {
 public:
  explicit PlanningEvaluation(const PlanningEvalConfig& config);
  ~PlanningEvaluation();
  /// One cycle with image noise seed `seed`.
  CycleReport run(uint64_t seed);

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace cellsight
