// How a rigid part can rest on a flat table: the facets of its convex hull over which its centre
// of mass lies (a body on a plane touches it with a hull facet, and stays only if the centre of
// mass is above that facet). The matcher turns these into pose hypotheses for parts lying on the
// support (MatchingConfig::rest_hypotheses).
#pragma once
#include <Eigen/Geometry>

#include <vector>

namespace cellsight {

struct RestPose {
  /// model frame → a frame whose +z is the table's normal (the resting facet faces −z)
  Eigen::Matrix3d R = Eigen::Matrix3d::Identity();
  /// how far the model origin lies above the table in that rest (the facet's distance from it)
  double height = 0;
  double area = 0;    ///< the resting facet's area (m²)
  double margin = 0;  ///< how far inside the facet the centre of mass lies (m): how stable the rest is
};

/// The stable rests of a part with these vertices (mesh vertices, or a cloud's points) and centre
/// of mass: every facet of their convex hull (coplanar faces merged) with the centre of mass at
/// least `min_margin` inside it, the largest facet first. Fewer than four points, or points
/// that span no volume: none.
std::vector<RestPose> stableRests(const std::vector<Eigen::Vector3d>& vertices, const Eigen::Vector3d& centre,
                                  double min_margin = 1e-3);

}  // namespace cellsight
