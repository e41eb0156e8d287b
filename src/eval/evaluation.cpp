#include "cellsight/eval/evaluation.hpp"

#include <algorithm>
#include <cmath>
#include <limits>

namespace cellsight {

double pointTriangleDistance(const Eigen::Vector3d& p, const Eigen::Vector3d& a,
                             const Eigen::Vector3d& b, const Eigen::Vector3d& c) {
  return (p - closestPointOnTriangle(p, a, b, c)).norm();
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

namespace cellsight {

LineCentreErrors lineCentreErrors(const ScannerRenderer& renderer, const Eigen::Isometry3d& T_base_flange,
                                  const LineExtractionConfig& config, uint64_t seed) {
  const Scene& scene = renderer.geometry().scene();
  const CameraIntrinsics& K = scene.scanner_camera.intrinsics;
  const Eigen::Isometry3d T_cam_base = scene.scanner_camera.T_base_camera.inverse();
  // Sheet ∩ table: a point and direction in the base frame.
  const Plane sheet = laserPlane(T_base_flange * scene.laser.T_flange_laser);
  const Eigen::Vector3d dir = sheet.n.cross(Eigen::Vector3d::UnitZ()).normalized();
  const Eigen::Vector3d o = (T_base_flange * scene.laser.T_flange_laser).translation();
  Eigen::Vector3d q(o.x(), o.y(), scene.table.z);
  const Eigen::Vector3d in_plane(sheet.n.x(), sheet.n.y(), 0);
  q -= sheet.distance(q) / in_plane.squaredNorm() * in_plane;
  auto image = [&](double s) { return K.project(T_cam_base * (q + s * dir)); };
  // Analytic centre at column u: bisection on s for image(s).x == u.
  auto rowAt = [&](double u, double& v) {
    double lo = -1.0, hi = 1.0;
    const bool inc = image(hi).x() > image(lo).x();
    for (int i = 0; i < 80; ++i) {
      const double mid = 0.5 * (lo + hi);
      if ((image(mid).x() < u) == inc) lo = mid; else hi = mid;
    }
    v = image(0.5 * (lo + hi)).y();
    return v >= 0 && v < K.height;
  };
  const cv::Mat img = renderer.render(T_base_flange, seed);
  LineExtractionConfig c = config;
  c.line_along_rows = true;
  const auto pts = extractLine(img, c);
  // The lit extent: columns where the noise-free laser is present.
  const cv::Mat clean = renderer.renderLaserOnly(T_base_flange);
  cv::Mat colmax;
  cv::reduce(clean, colmax, 0, cv::REDUCE_MAX, CV_32F);
  int first = -1, last = -1;
  for (int u = 0; u < colmax.cols; ++u) {
    if (colmax.at<float>(0, u) > 20.f) {
      if (first < 0) first = u;
      last = u;
    }
  }
  LineCentreErrors e;
  if (first < 0) return e;
  const int margin = (last - first) / 10;
  first += margin;
  last -= margin;
  e.expected = static_cast<size_t>(last - first + 1);
  double s2 = 0, s1 = 0;
  for (const auto& p : pts) {
    if (p.u < first || p.u > last) continue;
    double v;
    if (!rowAt(p.u, v)) continue;
    const double err = p.v - v;
    s2 += err * err;
    s1 += std::abs(err);
    e.max_px = std::max(e.max_px, std::abs(err));
    ++e.columns;
  }
  if (e.columns) {
    e.rms_px = std::sqrt(s2 / static_cast<double>(e.columns));
    e.mean_px = s1 / static_cast<double>(e.columns);
  }
  return e;
}

}  // namespace cellsight
