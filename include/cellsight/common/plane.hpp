// A plane n·p + d = 0 and the laser's light sheet as one (the plane y = 0 of the laser frame).
// Small on purpose: messages, clustering and calibration use it without the renderer.
#pragma once
#include <Eigen/Geometry>

namespace cellsight {

/// A plane n·p + d = 0 with unit n.
struct Plane {
  Eigen::Vector3d n = Eigen::Vector3d::UnitZ();
  double d = 0.0;
  double distance(const Eigen::Vector3d& p) const { return n.dot(p) + d; }
};

/// The light sheet (plane y = 0 of the laser frame) expressed in the frame of T_frame_laser.
inline Plane laserPlane(const Eigen::Isometry3d& T_frame_laser) {
  Plane p;
  p.n = T_frame_laser.linear().col(1);
  p.d = -p.n.dot(T_frame_laser.translation());
  return p;
}

}  // namespace cellsight
