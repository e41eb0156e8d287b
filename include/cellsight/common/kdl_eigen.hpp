// Frames between KDL and Eigen, for the translation units that use KDL (the simulated robot's
// error model, the planner's arm). Header-only: the common layer itself does not link KDL.
#pragma once
#include <kdl/frames.hpp>

#include <Eigen/Geometry>

namespace cellsight {

inline KDL::Frame toKdl(const Eigen::Isometry3d& T) {
  const Eigen::Matrix3d R = T.linear();
  return KDL::Frame(KDL::Rotation(R(0, 0), R(0, 1), R(0, 2), R(1, 0), R(1, 1), R(1, 2), R(2, 0), R(2, 1), R(2, 2)),
                    KDL::Vector(T.translation().x(), T.translation().y(), T.translation().z()));
}

inline Eigen::Isometry3d fromKdl(const KDL::Frame& F) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  for (int i = 0; i < 3; ++i) {
    T.translation()(i) = F.p(i);
    for (int j = 0; j < 3; ++j) T.linear()(i, j) = F.M(i, j);
  }
  return T;
}

}  // namespace cellsight
