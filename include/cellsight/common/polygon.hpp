// Small plane and polygon helpers shared by the scene generator and the matcher's rest poses.
#pragma once
#include <Eigen/Geometry>

#include <vector>

namespace cellsight {

/// Convex hull of points in a plane (Andrew's monotone chain), counter-clockwise; fewer than
/// three points come back as given.
std::vector<Eigen::Vector2d> convexHull2d(std::vector<Eigen::Vector2d> points);

/// How far q lies inside a counter-clockwise convex polygon: its least distance to an edge's
/// line, negative outside (−infinity for fewer than three corners).
double insideMargin(const std::vector<Eigen::Vector2d>& polygon, const Eigen::Vector2d& q);

/// Whether q lies inside a counter-clockwise convex polygon by at least `margin` (false for
/// fewer than three corners).
inline bool insideBy(const std::vector<Eigen::Vector2d>& polygon, const Eigen::Vector2d& q, double margin) {
  return insideMargin(polygon, q) >= margin;
}

/// Rotation taking unit vector `from` onto unit vector `to` (opposite vectors: a half turn about
/// an axis across `from`; Eigen's FromTwoVectors gave NaN there in an optimised build).
Eigen::Matrix3d rotationBetween(const Eigen::Vector3d& from, const Eigen::Vector3d& to);

}  // namespace cellsight
