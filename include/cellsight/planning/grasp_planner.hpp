// From located parts to robot motions (thesis §3 "Grasp", and its future work): for a located
// part, the grasp candidates of its model (cached per model), scored and pruned with the reason;
// the assembly sequence approach → grasp → lift → pre-place → insert along v_i → release →
// retreat, with the target = located base part · T_0i; collision-free paths for every step
// (joint paths between the named poses, straight lines for approach, lift, insert and retreat)
// and one time-parameterised trajectory. The world changes only when the caller commits a plan.
#pragma once
#include <map>
#include <memory>
#include <string>
#include <vector>

#include "cellsight/common/mesh.hpp"
#include "cellsight/common/model_info.hpp"
#include "cellsight/planning/collision_world.hpp"
#include "cellsight/planning/grasps.hpp"
#include "cellsight/planning/motion_planner.hpp"

namespace cellsight {

/// config/assembly.yaml: which parts go into the assembly, in which order, and the motion
/// distances. The targets are each model's T_0i and v_i (model.yaml) on the located base part.
struct AssemblyConfig {
  std::string base_model;             ///< the part the others are placed on; it stays where it lies
  std::vector<std::string> order;     ///< models, placed in this order
  double approach_distance = 0.05;    ///< m, pre-grasp back along the tool axis
  double lift_height = 0.06;          ///< m, straight up after closing the jaws
  double preplace_distance = 0.04;    ///< m, before the target against v_i
  double retreat_distance = 0.05;     ///< m, back along the tool axis after opening
  /// m: the carried part may touch the part it is inserted into only on the insertion's last
  /// stretch this long (contact at the target); before it, it is checked like any obstacle
  double insert_contact_distance = 0.003;
  /// a located part this close to its target (m, and rad about it, symmetry-aware) is placed
  double placed_tolerance = 0.003, placed_tolerance_rad = 0.05;
  double min_approach_down = -0.1;    ///< the tool axis' downward component at least this (no grasp from below)
  int max_candidates = 40;            ///< grasp candidates fully planned per part before giving up
  JointVector home = (JointVector() << 0.0, 0.5, 0.64, 0.0, 0.43, 0.0).finished();  ///< rad: flange down above the table
};

/// Loads config/assembly.yaml (strict keys). Throws ConfigError naming file and key.
AssemblyConfig loadAssemblyConfig(const std::string& path);

/// A located part as the planner receives it.
struct LocatedPart {
  std::string name;   ///< instance name (object/<n>)
  std::string model;
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();  ///< model frame in base_link
  /// other poses the scan cannot tell `pose` from (PartDetection::ambiguous_poses, base_link):
  /// where the part is to go, or where the base part's targets are, is not known (kAmbiguousPose)
  std::vector<Eigen::Isometry3d> ambiguous_poses;
};

enum class PlanStatus {
  kOk, kUnknownModel, kNotInAssembly, kBasePart, kNoBase, kNoGrasp, kUnreachable, kNoPath, kBadInput,
  kNothingLeft,  ///< planNext(): every located part of the assembly is placed or was refused
  kAmbiguousPose  ///< the part's or the base part's pose is ambiguous (LocatedPart::ambiguous_poses)
};
const char* planStatusName(PlanStatus s);

struct NamedPose {
  std::string name;
  Eigen::Isometry3d T_base_tcp = Eigen::Isometry3d::Identity();
  JointVector q = JointVector::Zero();
};

/// One motion of the plan: a joint or straight-line path, the jaws' opening, whether the part is held.
struct PlanSegment {
  std::string name;   ///< "to_pre_grasp", "approach", "lift", "transfer", "insert", "retreat"
  bool cartesian = false;
  bool carrying = false;
  double opening = 0;  ///< m during the segment
  std::vector<JointVector> path;
};

struct PartPlan {
  PlanStatus status = PlanStatus::kBadInput;
  std::string reason;
  LocatedPart part;
  GraspCandidate grasp;
  Eigen::Isometry3d T_base_target = Eigen::Isometry3d::Identity();  ///< where the part is to end (with the symmetry turn used)
  std::vector<NamedPose> poses;     ///< pre_grasp, grasp, lift, pre_place, place, retreat
  std::vector<PlanSegment> segments;
  TimedTrajectory trajectory;
  size_t grasp_index = 0, release_index = 0;  ///< trajectory points where the jaws close / open
  double grip_opening = 0;                    ///< m: the part's width (jaws closed on it)
  std::map<std::string, int> pruned;          ///< candidates refused, by reason
  int candidates = 0, candidates_tried = 0;
  double seconds = 0;
  bool sampled = false;  ///< a joint segment needed OMPL
  /// planNext(): parts of the assembly refused before this one, "<name>: <status>: <reason>"
  std::vector<std::string> passed_over;
};

class GraspPlanner {
 public:
  /// `models`: model id → (metadata, mesh). Throws std::invalid_argument when the assembly's base
  /// or ordered models are unknown.
  GraspPlanner(const ArmModel& arm, const AssemblyConfig& assembly, const GripperConfig& gripper,
               const MotionPlannerConfig& motion, std::map<std::string, std::pair<ModelInfo, std::shared_ptr<const TriangleMesh>>> models);

  /// The collision world for a scene: the table, every located part of a known model as its
  /// mesh, and the scan points they leave unexplained. Remembers which object each part is. A
  /// part located at its target already (placed_tolerance: e.g. after a rescan) counts as placed,
  /// unless the base part's pose is ambiguous or one of the part's own ambiguous_poses is off
  /// the target (LocatedPart::ambiguous_poses).
  void setScene(CollisionWorld world, const std::vector<LocatedPart>& parts, const std::vector<Eigen::Vector3f>& scan);
  const CollisionWorld& world() const { return *world_; }
  const std::vector<LocatedPart>& parts() const { return parts_; }

  /// Plans part `index` of setScene's parts from joint state `start`.
  PartPlan plan(size_t index, const JointVector& start) const;
  /// The next part of the assembly order that is located, not placed yet, and plans; when none
  /// plans, the first refusal. `index` receives the part chosen (or parts().size()).
  PartPlan planNext(const JointVector& start, size_t* index) const;
  /// The part was carried out as planned: it leaves its place and lies at the target.
  void commit(size_t index, const PartPlan& plan);
  bool placed(size_t index) const { return placed_.count(index) > 0; }
  /// planNext() passes this part over from now on (it was refused; it stays where it lies).
  void skip(size_t index) { skipped_[index] = 1; }

  /// The grasp candidates of a model (computed once).
  const std::vector<GraspCandidate>& candidates(const std::string& model) const;

 private:
  const ArmModel& arm_;
  AssemblyConfig assembly_;
  GripperConfig gripper_;
  MotionPlanner motion_;
  std::map<std::string, std::pair<ModelInfo, std::shared_ptr<const TriangleMesh>>> models_;
  mutable std::map<std::string, std::vector<GraspCandidate>> candidates_;
  std::unique_ptr<CollisionWorld> world_;
  std::vector<LocatedPart> parts_;
  std::vector<int> object_ids_;
  std::map<size_t, int> placed_, skipped_;
};

}  // namespace cellsight
