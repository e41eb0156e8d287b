#include "cellsight/triangulation.hpp"

#include <cmath>

namespace cellsight {

std::vector<ProfilePoint> triangulate(const std::vector<LinePoint>& line,
                                      const CameraIntrinsics& camera, const Plane& plane,
                                      const TriangulationConfig& config) {
  std::vector<ProfilePoint> out;
  out.reserve(line.size());
  const double sin_min = std::sin(config.min_ray_plane_angle);
  for (const auto& lp : line) {
    const Eigen::Vector2d x = camera.undistortPixel({lp.u, lp.v});
    const Eigen::Vector3d r(x.x(), x.y(), 1.0);
    const double nr = plane.n.dot(r);
    if (std::abs(nr) < sin_min * r.norm()) continue;
    const double t = -plane.d / nr;  // camera centre at the origin
    if (t <= 0) continue;
    const Eigen::Vector3d p = t * r;
    const double range = p.norm();
    if (range < config.min_range || range > config.max_range) continue;
    ProfilePoint pp;
    pp.p = p;
    pp.intensity = lp.peak;
    pp.u = lp.u;
    pp.v = lp.v;
    out.push_back(pp);
  }
  return out;
}

}  // namespace cellsight
