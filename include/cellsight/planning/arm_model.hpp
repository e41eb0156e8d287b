// The robot arm as the planner sees it: a URDF (urdf/cellsight_arm.urdf) read with urdfdom and
// kdl_parser into a KDL chain base_link → tool0, its joint limits, the collision shapes of every
// link, and the tool centre point. Forward kinematics for every link, inverse kinematics with
// joint limits (KDL's Levenberg–Marquardt solver from several seeds, the in-limit solution nearest
// the seed kept). KDL and urdfdom stay behind the pimpl.
#pragma once
#include <Eigen/Geometry>
#include <array>
#include <memory>
#include <optional>
#include <string>
#include <vector>

namespace cellsight {

using JointVector = Eigen::Matrix<double, 6, 1>;
using Isometries = std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>>;

/// A link's collision shape (from the URDF's <collision>): box (size x y z), cylinder (radius,
/// length along its z) or sphere (radius); `origin` is the shape's pose in the link frame.
struct CollisionShape {
  enum class Type { kBox, kCylinder, kSphere } type = Type::kBox;
  Eigen::Vector3d size = Eigen::Vector3d::Zero();  ///< box: x y z; cylinder: radius, length, 0; sphere: radius
  Eigen::Isometry3d origin = Eigen::Isometry3d::Identity();
  std::string link;
  int chain_index = 0;  ///< pose = chain frame `chain_index` (0 = base_link, 1..6 = link_1..6, 7 = tool0) · `in_chain`
  Eigen::Isometry3d in_chain = Eigen::Isometry3d::Identity();  ///< link frame in that chain frame at q = 0
  bool finger = false;  ///< a finger: its link slides along `slide_axis` (link frame) by half the opening
  Eigen::Vector3d slide_axis = Eigen::Vector3d::Zero();
};

struct IkConfig {
  int max_seeds = 8;            ///< seeds tried: the given one, then fixed branch seeds
  double position_tolerance = 1e-6;   ///< m, accepted solution
  double rotation_tolerance = 1e-5;   ///< rad
};

/// Not re-entrant (the KDL solvers keep scratch state): one ArmModel per thread.
class ArmModel {
 public:
  /// Reads a URDF file: the chain from `base_link` to `tool0`, the `tcp` link (fixed on tool0) and
  /// the collision shapes of every link on and below the chain. Throws ConfigError naming what
  /// is missing (a link, a limit, a six-joint chain).
  static ArmModel fromUrdfFile(const std::string& path);
  static ArmModel fromUrdfString(const std::string& xml, const std::string& source = "<string>");
  ArmModel(ArmModel&&) noexcept;
  ArmModel& operator=(ArmModel&&) noexcept;
  ArmModel(const ArmModel&);
  ~ArmModel();

  const std::array<std::string, 6>& jointNames() const { return joint_names_; }
  const JointVector& lower() const { return lower_; }
  const JointVector& upper() const { return upper_; }
  const JointVector& maxVelocity() const { return max_velocity_; }
  bool withinLimits(const JointVector& q, double margin = 0) const;
  /// tool0 in tool centre point, i.e. T_tool0_tcp.
  const Eigen::Isometry3d& toolTcp() const { return tool0_tcp_; }
  double maxJawOpening() const { return max_opening_; }
  const std::vector<CollisionShape>& shapes() const { return shapes_; }

  /// tool0 (= flange) in base_link.
  Eigen::Isometry3d fk(const JointVector& q) const;
  /// Chain frames in base_link: 0 = base_link, 1..6 = link_1..link_6, 7 = tool0 (one per KDL segment).
  Isometries chainFrames(const JointVector& q) const;
  /// Each shape's pose in base_link (fingers opened to `opening`, metres between the pads).
  Isometries shapePoses(const JointVector& q, double opening) const;

  /// tool0 pose → joints within the limits, nearest `seed` (max-norm of the joint change) among
  /// the solutions from the seeds; nullopt when no seed converges inside the limits.
  std::optional<JointVector> ik(const Eigen::Isometry3d& T_base_tool0, const JointVector& seed,
                                const IkConfig& config = {}) const;

 private:
  ArmModel();
  std::array<std::string, 6> joint_names_;
  JointVector lower_, upper_, max_velocity_;
  Eigen::Isometry3d tool0_tcp_ = Eigen::Isometry3d::Identity();
  double max_opening_ = 0;
  std::vector<CollisionShape> shapes_;
  struct Kdl;
  std::unique_ptr<Kdl> kdl_;
};

/// The joint-space distance used everywhere: the largest single joint change (rad).
inline double jointDistance(const JointVector& a, const JointVector& b) { return (a - b).cwiseAbs().maxCoeff(); }

}  // namespace cellsight
