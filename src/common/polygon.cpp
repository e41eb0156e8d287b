#include "cellsight/common/polygon.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace cellsight {
namespace {

using Vec2 = Eigen::Vector2d;

double cross(const Vec2& o, const Vec2& a, const Vec2& b) {
  return (a.x() - o.x()) * (b.y() - o.y()) - (a.y() - o.y()) * (b.x() - o.x());
}

}  // namespace

std::vector<Vec2> convexHull2d(std::vector<Vec2> p) {
  std::sort(p.begin(), p.end(), [](const Vec2& a, const Vec2& b) { return a.x() < b.x() || (a.x() == b.x() && a.y() < b.y()); });
  if (p.size() < 3) return p;
  std::vector<Vec2> h(2 * p.size());
  size_t k = 0;
  for (size_t i = 0; i < p.size(); ++i) {
    while (k >= 2 && cross(h[k - 2], h[k - 1], p[i]) <= 0) --k;
    h[k++] = p[i];
  }
  for (size_t i = p.size() - 1, t = k + 1; i > 0; --i) {
    while (k >= t && cross(h[k - 2], h[k - 1], p[i - 1]) <= 0) --k;
    h[k++] = p[i - 1];
  }
  h.resize(k - 1);
  return h;
}

double insideMargin(const std::vector<Vec2>& poly, const Vec2& q) {
  if (poly.size() < 3) return -std::numeric_limits<double>::infinity();
  double m = std::numeric_limits<double>::infinity();
  for (size_t i = 0; i < poly.size(); ++i) {
    const Vec2 a = poly[i], b = poly[(i + 1) % poly.size()];
    m = std::min(m, cross(a, b, q) / (b - a).norm());
  }
  return m;
}

Eigen::Matrix3d rotationBetween(const Eigen::Vector3d& from, const Eigen::Vector3d& to) {
  if (from.dot(to) < -1 + 1e-9) {
    Eigen::Vector3d axis = from.cross(Eigen::Vector3d::UnitX());
    if (axis.norm() < 1e-6) axis = from.cross(Eigen::Vector3d::UnitY());
    return Eigen::AngleAxisd(M_PI, axis.normalized()).toRotationMatrix();
  }
  return Eigen::Quaterniond::FromTwoVectors(from, to).toRotationMatrix();
}

}  // namespace cellsight
