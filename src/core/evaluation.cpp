#include "cellsight/evaluation.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace cellsight {

double pointTriangleDistance(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                             const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  // Closest point on a triangle by Voronoi regions (Ericson, Real-Time Collision Detection §5.1.5).
  const Eigen::Vector3d ab = b - a, ac = c - a, ap = p - a;
  const double d1 = ab.dot(ap), d2 = ac.dot(ap);
  if (d1 <= 0 && d2 <= 0) return (p - a).norm();
  const Eigen::Vector3d bp = p - b;
  const double d3 = ab.dot(bp), d4 = ac.dot(bp);
  if (d3 >= 0 && d4 <= d3) return (p - b).norm();
  const double vc = d1 * d4 - d3 * d2;
  if (vc <= 0 && d1 >= 0 && d3 <= 0) return (p - (a + d1 / (d1 - d3) * ab)).norm();
  const Eigen::Vector3d cp = p - c;
  const double d5 = ab.dot(cp), d6 = ac.dot(cp);
  if (d6 >= 0 && d5 <= d6) return (p - c).norm();
  const double vb = d5 * d2 - d1 * d6;
  if (vb <= 0 && d2 >= 0 && d6 <= 0) return (p - (a + d2 / (d2 - d6) * ac)).norm();
  const double va = d3 * d6 - d5 * d4;
  if (va <= 0 && (d4 - d3) >= 0 && (d5 - d6) >= 0) {
    return (p - (b + (d4 - d3) / ((d4 - d3) + (d5 - d6)) * (c - b))).norm();
  }
  const double denom = 1.0 / (va + vb + vc);
  return (p - (a + ab * (vb * denom) + ac * (vc * denom))).norm();
}

SurfaceDistance::SurfaceDistance(const Scene& scene) : table_(scene.table) {
  for (const auto& o : scene.objects) {
    const TriangleMesh m = loadValidMesh(o.info.mesh_file);
    Object obj;
    for (const auto& f : m.faces) {
      obj.a.push_back(o.T_base_object * m.vertices[f[0]].cast<double>());
      obj.b.push_back(o.T_base_object * m.vertices[f[1]].cast<double>());
      obj.c.push_back(o.T_base_object * m.vertices[f[2]].cast<double>());
      obj.box.extend(obj.a.back());
      obj.box.extend(obj.b.back());
      obj.box.extend(obj.c.back());
    }
    objects_.push_back(std::move(obj));
  }
}

double SurfaceDistance::operator()(const Eigen::Vector3d& p) const {
  double best = std::numeric_limits<double>::infinity();
  const Eigen::Vector2d rel = p.head<2>() - table_.center;
  if (std::abs(rel.x()) <= table_.size.x() / 2 && std::abs(rel.y()) <= table_.size.y() / 2) {
    best = std::abs(p.z() - table_.z);
  }
  for (const auto& o : objects_) {
    if (o.box.exteriorDistance(p) >= best) continue;
    for (size_t i = 0; i < o.a.size(); ++i) {
      best = std::min(best, pointTriangleDistance(p, o.a[i], o.b[i], o.c[i]));
    }
  }
  return best;
}

SurfaceErrorStats SurfaceDistance::stats(const std::vector<Eigen::Vector3d>& points) const {
  SurfaceErrorStats s;
  std::vector<double> errs;
  errs.reserve(points.size());
  for (const auto& p : points) errs.push_back((*this)(p));
  s.points = errs.size();
  if (errs.empty()) return s;
  double s2 = 0, s1 = 0;
  for (double e : errs) {
    s2 += e * e;
    s1 += e;
    s.max = std::max(s.max, e);
  }
  s.rms = std::sqrt(s2 / static_cast<double>(errs.size()));
  s.mean_abs = s1 / static_cast<double>(errs.size());
  std::nth_element(errs.begin(), errs.begin() + static_cast<long>(errs.size() * 99 / 100), errs.end());
  s.p99 = errs[errs.size() * 99 / 100];
  return s;
}

}  // namespace cellsight
