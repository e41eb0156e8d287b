// Poses as robot controllers write them. The robot bridge sends user frames in the convention the
// controller speaks:
//   kuka    X Y Z [mm]  A B C [deg],  R = Rz(A)·Ry(B)·Rx(C)
//   abb     x y z [mm]  q1 q2 q3 q4,  q1 = w (scalar first, q1 ≥ 0)
//   fanuc   X Y Z [mm]  W P R [deg],  R = Rz(R)·Ry(P)·Rx(W)
//   rep103  x y z [m]   roll pitch yaw [rad], R = Rz(yaw)·Ry(pitch)·Rx(roll)
#pragma once
#include <Eigen/Geometry>
#include <string>

namespace cellsight {

enum class PoseConvention { kKuka, kAbb, kFanuc, kRep103 };

/// kuka | abb | fanuc | rep103; throws std::invalid_argument naming the choices.
PoseConvention parsePoseConvention(const std::string& name);
std::string poseConventionName(PoseConvention c);

/// The pose as space-separated numbers (6 or 7 fields; mm to 3 decimals, angles to 4,
/// quaternions to 7, metres to 6, radians to 7).
std::string formatRobotPose(const Eigen::Isometry3d& T, PoseConvention c);
/// The inverse (for controllers' replies and tests); throws std::invalid_argument on a wrong
/// field count, a non-number or a non-finite value.
Eigen::Isometry3d parseRobotPose(const std::string& fields, PoseConvention c);

}  // namespace cellsight
