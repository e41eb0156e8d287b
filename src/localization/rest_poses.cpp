#include "cellsight/localization/rest_poses.hpp"

#include <pcl/surface/convex_hull.h>

#include <Eigen/Eigenvalues>

#include <algorithm>
#include <cmath>
#include <limits>

#include "cellsight/common/polygon.hpp"

namespace cellsight {

std::vector<RestPose> stableRests(const std::vector<Eigen::Vector3d>& vertices, const Eigen::Vector3d& centre,
                                  double min_margin) {
  std::vector<RestPose> out;
  if (vertices.size() < 4 || !centre.allFinite()) return out;
  pcl::PointCloud<pcl::PointXYZ>::Ptr cloud(new pcl::PointCloud<pcl::PointXYZ>);
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  Eigen::Vector3d lo = Eigen::Vector3d::Constant(std::numeric_limits<double>::infinity()), hi = -lo;
  size_t finite = 0;
  for (const auto& v : vertices) {
    if (!v.allFinite()) continue;
    mean += v;
    lo = lo.cwiseMin(v);
    hi = hi.cwiseMax(v);
    ++finite;
  }
  if (finite < 4) return out;
  const double size = (hi - lo).norm();
  if (!(size > 0)) return out;
  // qhull in the part's own scale: coordinates about their mean, in units of the part's size
  mean /= static_cast<double>(finite);
  for (const auto& v : vertices) {
    if (!v.allFinite()) continue;
    const Eigen::Vector3d q = (v - mean) / size;
    cloud->push_back(pcl::PointXYZ(static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z())));
  }
  // points that span no volume have no hull (qhull would stop the process on them)
  Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
  for (const auto& p : *cloud) {
    const Eigen::Vector3d q(p.x, p.y, p.z);
    cov += q * q.transpose();
  }
  const Eigen::Vector3d ev = Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d>(cov / static_cast<double>(cloud->size())).eigenvalues();
  if (!(ev.minCoeff() > 1e-10)) return out;
  pcl::ConvexHull<pcl::PointXYZ> hull;
  hull.setDimension(3);
  hull.setInputCloud(cloud);
  pcl::PointCloud<pcl::PointXYZ> hv;
  std::vector<pcl::Vertices> polygons;
  try {
    hull.reconstruct(hv, polygons);
  } catch (const std::exception&) {
    return out;
  }
  if (polygons.empty() || hull.getDimension() != 3) return out;
  // facets: outward normal and offset of each hull triangle, coplanar ones grouped
  struct Facet {
    Eigen::Vector3d n;
    double offset = 0, area = 0;
  };
  std::vector<Facet> facets;
  auto point = [&](uint32_t i) -> Eigen::Vector3d { return Eigen::Vector3d(hv[i].x, hv[i].y, hv[i].z) * size + mean; };
  for (const auto& poly : polygons) {
    if (poly.vertices.size() < 3) continue;
    const Eigen::Vector3d a = point(poly.vertices[0]), b = point(poly.vertices[1]), c = point(poly.vertices[2]);
    Eigen::Vector3d n = (b - a).cross(c - a);
    const double area = 0.5 * n.norm();
    if (!(area > 0)) continue;
    n.normalize();
    if (n.dot(a - mean) < 0) n = -n;  // the hull holds its vertices' mean
    const double offset = n.dot(a);
    auto same = std::find_if(facets.begin(), facets.end(), [&](const Facet& f) {
      return f.n.dot(n) > 1 - 1e-6 && std::abs(f.offset - offset) < 1e-6 * size;
    });
    if (same == facets.end()) {
      facets.push_back({n, offset, area});
    } else {
      same->area += area;
    }
  }
  for (const auto& f : facets) {
    RestPose r;
    r.R = rotationBetween(f.n, -Eigen::Vector3d::UnitZ());
    // the facet: the vertices on its plane, in the table's plane after the turn
    std::vector<Eigen::Vector2d> on;
    for (const auto& v : vertices)
      if (v.allFinite() && f.n.dot(v) > f.offset - 1e-6 * size) on.push_back((r.R * v).head<2>());
    const std::vector<Eigen::Vector2d> poly = convexHull2d(on);
    const Eigen::Vector2d c = (r.R * centre).head<2>();
    r.margin = insideMargin(poly, c);
    if (!(r.margin >= min_margin)) continue;
    r.height = f.offset;  // the facet lies at z = −offset after the turn
    r.area = f.area;
    out.push_back(r);
  }
  std::sort(out.begin(), out.end(), [](const RestPose& a, const RestPose& b) { return a.area > b.area; });
  return out;
}

}  // namespace cellsight
