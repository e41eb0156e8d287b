// The simulated robot's positioning error: where the flange really goes when the controller is
// told (and reports) a pose. A 6-axis arm of the 6-kg class (KUKA KR 6 R900-like standard DH
// parameters, base at base_link) is solved for the commanded pose with its nominal parameters
// (what the controller believes) and the joint angles are then carried through perturbed
// parameters (the arm as built: joint zero offsets, link lengths, twists), plus a small
// per-move repeatability scatter. Forward and inverse kinematics come from KDL.
#pragma once
#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <memory>

namespace cellsight {

struct RobotErrorConfig {
  bool enabled = false;              ///< false: the flange goes exactly where it is told
  double joint_offset_deg = 0.01;    ///< σ of each joint's zero offset
  double link_mm = 0.1;              ///< σ of each DH length (a, d)
  double twist_deg = 0.01;           ///< σ of each DH twist (α)
  double repeatability_mm = 0.008;   ///< σ per axis of the reached position, per move
  double repeatability_deg = 0.001;  ///< σ per axis of the reached orientation, per move
  uint64_t seed = 1;                 ///< draws the as-built parameters and the per-move scatter
};

/// One standard DH row: a, alpha, d, theta offset (metres, radians).
struct DhRow {
  double a, alpha, d, theta;
};

class RobotErrorModel {
 public:
  explicit RobotErrorModel(const RobotErrorConfig& config = {});
  ~RobotErrorModel();
  RobotErrorModel(RobotErrorModel&&) noexcept;
  RobotErrorModel& operator=(RobotErrorModel&&) noexcept;

  bool enabled() const { return config_.enabled; }
  const RobotErrorConfig& config() const { return config_; }
  /// The nominal arm (what the controller believes) and the arm as built.
  static std::array<DhRow, 6> nominalDh();
  const std::array<DhRow, 6>& builtDh() const { return built_; }

  /// Where the flange really is when commanded to (and reporting) `commanded`, on move number
  /// `move` (the repeatability scatter is drawn per move, reproducibly). Identity map when
  /// disabled. Throws std::runtime_error if the nominal arm cannot reach `commanded`.
  Eigen::Isometry3d actual(const Eigen::Isometry3d& commanded, uint64_t move) const;
  /// Where the flange really is when the controller holds the joints at `q` (standard DH, the
  /// nominal arm's joint convention; the URDF's joints are the same): the arm as built plus the
  /// per-move scatter; the nominal forward kinematics when disabled. No inverse kinematics, so no
  /// branch ambiguity: what a joint-space program (a grasp plan) really reaches.
  Eigen::Isometry3d actualAtJoints(const Eigen::Matrix<double, 6, 1>& q, uint64_t move) const;
  /// The nominal arm's flange at joints `q`.
  Eigen::Isometry3d nominalAtJoints(const Eigen::Matrix<double, 6, 1>& q) const;
  /// The systematic part only (no scatter).
  Eigen::Isometry3d actualSystematic(const Eigen::Isometry3d& commanded) const;
  /// What the controller reports when its flange really is at `actual_pose` (the inverse map,
  /// systematic part): a point taught by jogging the robot to a mark is reported here.
  Eigen::Isometry3d reported(const Eigen::Isometry3d& actual_pose) const;

 private:
  Eigen::Isometry3d withScatter(Eigen::Isometry3d T, uint64_t move) const;
  RobotErrorConfig config_;
  std::array<DhRow, 6> built_{};
  struct Kdl;
  std::unique_ptr<Kdl> kdl_;
};

}  // namespace cellsight
