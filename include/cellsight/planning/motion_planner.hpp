// Paths for the arm through the collision world: joint-space paths by OMPL (the straight joint
// edge first; RRTConnect and OMPL's path simplification when it collides), Cartesian straight
// lines for approach, lift, insertion and retreat (IK at every step, seeded by the previous
// solution, joint jumps refused), and a dense re-check of every edge at a stated joint
// resolution. Time parameterisation within the joint velocity and acceleration limits.
// OMPL stays behind this interface.
#pragma once
#include <array>
#include <optional>
#include <string>
#include <vector>

#include "cellsight/planning/arm_model.hpp"
#include "cellsight/planning/collision_world.hpp"

namespace cellsight {

struct MotionPlannerConfig {
  double planning_time = 0.5;      ///< s per OMPL query
  /// Edges are checked at steps that move no point of the arm, the gripper or a carried part
  /// farther than the collision padding (CollisionWorldConfig::padding): the padded shapes at
  /// the steps then cover the unpadded ones in between. The bound per joint j is
  /// |Δq_j| · reach[j] (reach: the farthest point beyond joint j's axis, carried part included).
  /// A step is also never longer than edge_resolution (rad).
  double edge_resolution = 0.05;
  /// m: this arm (0.9 m reach) with its gripper and a part reaching 0.1 m beyond the tcp
  std::array<double, 6> reach = {1.25, 1.2, 0.82, 0.35, 0.35, 0.15};
  double cartesian_step = 0.002;   ///< m (and cartesian_step / 0.05 rad) between Cartesian IK points
  double max_joint_jump = 0.1;     ///< rad between consecutive Cartesian IK solutions
  bool direct_first = true;        ///< try the straight joint edge before sampling
  bool simplify = true;            ///< OMPL's PathSimplifier on RRTConnect's path
  double simplify_time = 0.03;     ///< s the simplifier may take per path
  /// rrtconnect | rrt | prm; straight: the straight joint edge or nothing (peers: bench_planning)
  std::string planner = "rrtconnect";
  double velocity_scale = 0.5;     ///< share of the URDF joint velocity limits used
  double acceleration = 3.0;       ///< rad/s², every joint
};

/// What a path may touch: the world, the jaw opening, a carried part, an object it may touch.
struct CollisionContext {
  const CollisionWorld* world = nullptr;
  double opening = 0.08;
  const CarriedPart* carried = nullptr;
  int ignore_object = -1;
};

struct PathResult {
  bool ok = false;
  std::vector<JointVector> waypoints;  ///< first = start, last = goal
  std::string reason;
  double seconds = 0;
  bool sampled = false;  ///< OMPL was needed (the straight edge collided)
};

struct TimedTrajectory {
  std::vector<JointVector> positions, velocities;
  std::vector<double> times;  ///< s from the start
  double duration() const { return times.empty() ? 0.0 : times.back(); }
};

class MotionPlanner {
 public:
  MotionPlanner(const ArmModel& arm, const MotionPlannerConfig& config);
  const MotionPlannerConfig& config() const { return config_; }
  const ArmModel& arm() const { return arm_; }

  /// A collision-free joint path; `from` must itself be valid (or the reason says it is not).
  PathResult planJoint(const JointVector& from, const JointVector& to, const CollisionContext& ctx) const;
  /// tool0 moved along a straight line (position linear, orientation slerp) to `target`.
  PathResult planCartesian(const JointVector& from, const Eigen::Isometry3d& T_base_tool0_target,
                           const CollisionContext& ctx) const;
  /// The state check every planner uses.
  CollisionReport checkState(const JointVector& q, const CollisionContext& ctx) const;
  /// Check of the straight joint edge a → b: within limits and collision-free at every step.
  /// `resolution` ≤ 0: the certified stepping above; > 0: at most that many rad per step (a
  /// re-check). Fills `where` with the first bad step.
  bool edgeValid(const JointVector& a, const JointVector& b, const CollisionContext& ctx, double resolution = 0,
                 CollisionReport* where = nullptr) const;
  /// Every edge of a path, densely.
  bool pathValid(const std::vector<JointVector>& path, const CollisionContext& ctx, double resolution = 0,
                 CollisionReport* where = nullptr) const;

  /// Joint-space path: stops at every waypoint (trapezoid per edge, joints synchronised).
  TimedTrajectory timeJointPath(const std::vector<JointVector>& path) const;
  /// Steps the certified check takes on the edge a → b.
  int certifiedSteps(const JointVector& a, const JointVector& b, const CollisionContext& ctx) const;
  /// Dense smooth path (Cartesian): one trapezoid along the path's length.
  TimedTrajectory timeSmoothPath(const std::vector<JointVector>& path) const;

 private:
  const ArmModel& arm_;
  MotionPlannerConfig config_;
};

/// Appends `b` to `a` (b's times shifted; b's first point dropped when it equals a's last).
void appendTrajectory(TimedTrajectory& a, const TimedTrajectory& b);

}  // namespace cellsight
