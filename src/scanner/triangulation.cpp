#include "cellsight/scanner/triangulation.hpp"

#include <cmath>

namespace cellsight {

UndistortionMap::UndistortionMap(const CameraIntrinsics& camera) : camera_(camera) {
  const int w = camera.width, h = camera.height;
  xy_.resize(static_cast<size_t>(w) * static_cast<size_t>(h) * 2);
  for (int v = 0; v < h; ++v) {
    for (int u = 0; u < w; ++u) {
      const Eigen::Vector2d x = camera.undistortPixel({u, v});
      const size_t i = 2 * (static_cast<size_t>(v) * w + u);
      xy_[i] = static_cast<float>(x.x());
      xy_[i + 1] = static_cast<float>(x.y());
    }
  }
}

Eigen::Vector2d UndistortionMap::operator()(double u, double v) const {
  const int w = camera_.width, h = camera_.height;
  if (!(u >= 0 && v >= 0 && u <= w - 1.000001 && v <= h - 1.000001)) {
    return camera_.undistortPixel({u, v});
  }
  const int u0 = static_cast<int>(u), v0 = static_cast<int>(v);
  const double fu = u - u0, fv = v - v0;
  const size_t i00 = 2 * (static_cast<size_t>(v0) * w + u0), i01 = i00 + 2,
               i10 = i00 + 2 * static_cast<size_t>(w), i11 = i10 + 2;
  Eigen::Vector2d r;
  for (int k = 0; k < 2; ++k) {
    r[k] = (1 - fv) * ((1 - fu) * xy_[i00 + k] + fu * xy_[i01 + k]) +
           fv * ((1 - fu) * xy_[i10 + k] + fu * xy_[i11 + k]);
  }
  return r;
}

namespace {
template <typename Undistort>
std::vector<ProfilePoint> triangulateWith(const std::vector<LinePoint>& line, Undistort&& undistort,
                                          const Plane& plane, const TriangulationConfig& config) {
  std::vector<ProfilePoint> out;
  out.reserve(line.size());
  const double sin_min = std::sin(config.min_ray_plane_angle);
  for (const auto& lp : line) {
    const Eigen::Vector2d x = undistort(lp.u, lp.v);
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
}  // namespace

std::vector<ProfilePoint> triangulate(const std::vector<LinePoint>& line, const UndistortionMap& map,
                                      const Plane& plane, const TriangulationConfig& config) {
  return triangulateWith(line, map, plane, config);
}

std::vector<ProfilePoint> triangulate(const std::vector<LinePoint>& line,
                                      const CameraIntrinsics& camera, const Plane& plane,
                                      const TriangulationConfig& config) {
  return triangulateWith(
      line, [&](double u, double v) { return camera.undistortPixel({u, v}); }, plane, config);
}

}  // namespace cellsight
