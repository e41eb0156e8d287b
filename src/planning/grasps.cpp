#include "cellsight/planning/grasps.hpp"

#include <cmath>
#include <random>
#include <stdexcept>

#include "cellsight/common/raycaster.hpp"

namespace cellsight {

namespace {

GraspCandidate measureWith(const RayCaster& caster, const Eigen::Vector3d& centroid, const Eigen::Isometry3d& T,
                           const GripperConfig& c, const std::string& source) {
  GraspCandidate g;
  g.T_model_tcp = T;
  g.source = source;
  const double far = 1.0;  // m: rays start outside any part
  const Eigen::Vector3d x = T.linear().col(0);
  double right = -1e9, left = 1e9;
  Eigen::Vector3d n_right = Eigen::Vector3d::Zero(), n_left = Eigen::Vector3d::Zero();
  int hits = 0;
  for (double fy : {-0.45, 0.0, 0.45}) {
    for (double fz : {-0.45, 0.0, 0.45}) {
      const Eigen::Vector3d o = T * Eigen::Vector3d(0, fy * c.pad_width, fz * c.pad_length);
      // from the right (+x) inwards, and from the left
      const RayHit hr = caster.intersect((o + far * x).cast<float>(), (-x).cast<float>(), 0.f, static_cast<float>(2 * far));
      const RayHit hl = caster.intersect((o - far * x).cast<float>(), x.cast<float>(), 0.f, static_cast<float>(2 * far));
      if (hr.hit) {
        ++hits;
        const double xr = far - hr.t;
        if (xr > right) {
          right = xr;
          n_right = hr.normal.cast<double>();
        }
      }
      if (hl.hit) {
        const double xl = -far + hl.t;
        if (xl < left) {
          left = xl;
          n_left = hl.normal.cast<double>();
        }
      }
    }
  }
  // the part must reach into the span of the open jaws
  if (hits == 0 || right < -0.5 * c.max_opening || left > 0.5 * c.max_opening) {
    g.reason = "nothing between the pads";
    return g;
  }
  g.width = right - left;
  // centre the tcp between the contacts (the jaws close symmetrically)
  g.T_model_tcp.translation() += x * (0.5 * (right + left));
  g.centroid_distance = (g.T_model_tcp.translation() - centroid).norm();
  const double cone = std::atan(c.friction);
  const double a_r = std::acos(std::clamp(n_right.dot(x), -1.0, 1.0));
  const double a_l = std::acos(std::clamp(n_left.dot(-x), -1.0, 1.0));
  g.friction_margin = cone - std::max(a_r, a_l);
  char buf[160];
  if (g.width + 2 * c.clearance > c.max_opening) {
    std::snprintf(buf, sizeof buf, "too wide for the jaws (%.1f mm + 2 x %.1f mm clearance > %.1f mm)", g.width * 1e3,
                  c.clearance * 1e3, c.max_opening * 1e3);
    g.reason = buf;
  } else if (g.width < c.min_width) {
    std::snprintf(buf, sizeof buf, "too thin to grip (%.1f mm)", g.width * 1e3);
    g.reason = buf;
  } else if (g.friction_margin < 0) {
    std::snprintf(buf, sizeof buf, "contact normals outside the friction cone (%.0f deg > %.0f deg)",
                  std::max(a_r, a_l) * 180 / M_PI, cone * 180 / M_PI);
    g.reason = buf;
  } else {
    g.valid = true;
  }
  return g;
}

Eigen::Isometry3d frameFrom(const Eigen::Vector3d& origin, const Eigen::Vector3d& x, const Eigen::Vector3d& z) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  const Eigen::Vector3d zz = (z - z.dot(x) * x).normalized();
  T.linear().col(0) = x;
  T.linear().col(2) = zz;
  T.linear().col(1) = zz.cross(x);
  T.translation() = origin;
  return T;
}

}  // namespace

std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>> symmetryRotations(
    const ModelInfo& info, int axial_steps, const Eigen::Vector3d& centroid) {
  std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>> out;
  int n = 1;
  Eigen::Vector3d axis = info.symmetry.axis.normalized();
  switch (info.symmetry.type) {
    case Symmetry::Type::kNone: n = 1; break;
    case Symmetry::Type::kDiscrete: n = std::max(1, info.symmetry.order); break;
    case Symmetry::Type::kAxial: n = std::max(1, axial_steps); break;
    case Symmetry::Type::kSpherical: n = std::max(1, axial_steps); axis = Eigen::Vector3d::UnitZ(); break;
  }
  const Eigen::Vector3d pivot = info.symmetry.type == Symmetry::Type::kSpherical ? centroid : Eigen::Vector3d::Zero();
  for (int k = 0; k < n; ++k) {
    out.push_back(Eigen::Translation3d(pivot) * Eigen::AngleAxisd(2 * M_PI * k / n, axis) * Eigen::Translation3d(-pivot));
  }
  return out;
}

GraspCandidate measureGrasp(const TriangleMesh& mesh, const Eigen::Isometry3d& T_model_tcp, const GripperConfig& config,
                            const std::string& source) {
  RayCaster caster;
  caster.addMesh(mesh, Eigen::Isometry3d::Identity());
  caster.commit();
  return measureWith(caster, mesh.surfaceCentroid(), T_model_tcp, config, source);
}

std::vector<GraspCandidate> graspCandidates(const ModelInfo& info, const TriangleMesh& mesh, const GripperConfig& c) {
  if (mesh.faces.empty()) throw std::invalid_argument("grasps: model '" + info.id + "' has an empty mesh");
  if (!(c.max_opening > 0) || !(c.pad_length > 0) || !(c.pad_width > 0) || c.yaw_steps < 1 || c.friction < 0) {
    throw std::invalid_argument("grasps: max_opening, pad sizes > 0, yaw_steps >= 1 and friction >= 0 required");
  }
  RayCaster caster;
  caster.addMesh(mesh, Eigen::Isometry3d::Identity());
  caster.commit();
  const Eigen::Vector3d centroid = mesh.surfaceCentroid();
  const auto sym = symmetryRotations(info, c.axial_steps, centroid);
  std::vector<GraspCandidate> out;
  // 1. the author's grasp frame, the jaws turned about its normal
  for (int k = 0; k < c.yaw_steps; ++k) {
    const Eigen::Isometry3d T = info.T_model_grasp * Eigen::Translation3d(0, 0, -c.grip_depth) *
                                Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()) *
                                Eigen::AngleAxisd(2 * M_PI * k / c.yaw_steps, Eigen::Vector3d::UnitZ());
    GraspCandidate g = measureWith(caster, centroid, T, c, "model");
    out.push_back(g);
    if (!g.valid) continue;
    for (size_t s = 1; s < sym.size(); ++s) {
      GraspCandidate e = g;
      e.T_model_tcp = sym[s] * g.T_model_tcp;
      e.source = "model+symmetry";
      out.push_back(e);
    }
  }
  // 2. antipodal pairs sampled on the surface (area-weighted)
  std::vector<double> cum;
  cum.reserve(mesh.faces.size());
  double total = 0;
  for (const auto& f : mesh.faces) {
    const Eigen::Vector3d a = mesh.vertices[f[0]].cast<double>(), b = mesh.vertices[f[1]].cast<double>(),
                          cc = mesh.vertices[f[2]].cast<double>();
    total += 0.5 * (b - a).cross(cc - a).norm();
    cum.push_back(total);
  }
  if (total <= 0) return out;
  std::mt19937_64 rng(c.seed);
  std::uniform_real_distribution<double> u01(0.0, 1.0);
  const double cone = std::atan(c.friction);
  for (int i = 0; i < c.antipodal_samples; ++i) {
    const size_t fi = static_cast<size_t>(std::lower_bound(cum.begin(), cum.end(), u01(rng) * total) - cum.begin());
    const auto& f = mesh.faces[std::min(fi, mesh.faces.size() - 1)];
    const Eigen::Vector3d a = mesh.vertices[f[0]].cast<double>(), b = mesh.vertices[f[1]].cast<double>(),
                          cc = mesh.vertices[f[2]].cast<double>();
    double r1 = u01(rng), r2 = u01(rng);
    if (r1 + r2 > 1) {
      r1 = 1 - r1;
      r2 = 1 - r2;
    }
    const Eigen::Vector3d p1 = a + r1 * (b - a) + r2 * (cc - a);
    const Eigen::Vector3d n1 = (b - a).cross(cc - a).normalized();
    if (!n1.allFinite()) continue;
    const Eigen::Vector3d d = -n1;
    const RayHit h = caster.intersect((p1 + 1e-5 * d).cast<float>(), d.cast<float>(), 0.f, static_cast<float>(c.max_opening));
    if (!h.hit) continue;
    const Eigen::Vector3d p2 = p1 + (1e-5 + h.t) * d;
    if (std::acos(std::clamp(h.normal.cast<double>().dot(d), -1.0, 1.0)) > cone) continue;
    const double w = (p2 - p1).norm();
    if (w < c.min_width || w + 2 * c.clearance > c.max_opening) continue;
    const Eigen::Vector3d mid = 0.5 * (p1 + p2);
    Eigen::Vector3d u = d.unitOrthogonal();
    const Eigen::Vector3d v = d.cross(u);
    const double phase = u01(rng) * 2 * M_PI / c.approach_steps;
    for (int k = 0; k < c.approach_steps; ++k) {
      const double th = phase + 2 * M_PI * k / c.approach_steps;
      const Eigen::Vector3d z = std::cos(th) * u + std::sin(th) * v;
      out.push_back(measureWith(caster, centroid, frameFrom(mid, d, z), c, "antipodal"));
    }
  }
  return out;
}

}  // namespace cellsight
