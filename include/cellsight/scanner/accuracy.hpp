// Scanner acceptance tests adapted from CMM standards (thesis §1): probing error MPE_P on a
// reference sphere, multi-orientation error MPE_AL, plane flatness.
#pragma once
#include <Eigen/Core>
#include <vector>

namespace cellsight {

struct SphereFit {
  Eigen::Vector3d center = Eigen::Vector3d::Zero();
  double radius = 0;
  double rms = 0;            ///< RMS of radial deviations
  double max_abs_dev = 0;    ///< MPE_P: largest |‖p − c‖ − r|
  double form_range = 0;     ///< max − min radial deviation
  size_t points = 0;
  bool ok = false;
};

/// Least-squares sphere: algebraic fit, then Gauss–Newton on geometric distances. With
/// `fixed_radius` > 0 only the centre is estimated (reference sphere of certified size).
SphereFit fitSphere(const std::vector<Eigen::Vector3d>& points, double fixed_radius = 0);

/// Smallest sphere containing all points (exact for small sets); returns its diameter. This is
/// MPE_AL when the points are the K fitted sphere centres.
double minimumEnclosingDiameter(const std::vector<Eigen::Vector3d>& points);

struct PlaneFit {
  Eigen::Vector3d normal = Eigen::Vector3d::UnitZ();
  double d = 0;           ///< n·p + d = 0
  double rms = 0;
  double flatness = 0;    ///< max − min signed distance
  bool ok = false;
};
PlaneFit fitPlane(const std::vector<Eigen::Vector3d>& points);

}  // namespace cellsight
