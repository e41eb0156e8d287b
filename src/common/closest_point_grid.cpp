#include "cellsight/common/closest_point_grid.hpp"

#include "cellsight/common/binary_io.hpp"

#include <algorithm>
#include <cmath>
#include <limits>
#include <stdexcept>

namespace cellsight {

ClosestPointGrid::ClosestPointGrid(const TriangleMesh& mesh, float cell, float margin, size_t max_cells)
    : margin_(margin) {
  if (!(cell > 0) || !(margin >= 0)) throw std::invalid_argument("ClosestPointGrid: cell must be > 0, margin >= 0");
  for (size_t i = 0; i < mesh.faces.size(); ++i) {
    const Eigen::Vector3i& f = mesh.faces[i];
    const Eigen::Vector3f n = (mesh.vertices[f[1]] - mesh.vertices[f[0]]).cross(mesh.vertices[f[2]] - mesh.vertices[f[0]]);
    if (!(n.norm() > 0) || !n.allFinite()) continue;  // degenerate: no normal, never closest alone
    faces_.push_back(f);
    face_ids_.push_back(static_cast<int>(i));
    normals_.push_back(n.normalized());
  }
  if (faces_.empty()) return;
  for (const auto& v : mesh.vertices) vertices_.push_back(v.cast<double>());
  const Eigen::AlignedBox3f box = mesh.bounds();
  const Eigen::Vector3f size = box.sizes() + Eigen::Vector3f::Constant(2 * margin);
  cell = std::max(cell, std::cbrt(size.prod() / static_cast<float>(max_cells)));
  cell_ = cell;
  inv_cell_ = 1.f / cell;
  origin_ = box.min() - Eigen::Vector3f::Constant(margin);
  size_t cells = 1;
  for (int a = 0; a < 3; ++a) {
    dims_[a] = std::max(1, static_cast<int>(std::ceil(size[a] / cell)));
    cells *= static_cast<size_t>(dims_[a]);
  }
  const double half_diag = 0.5 * std::sqrt(3.0) * cell;
  const double reach = margin + half_diag;  // cells whose centre is farther get no list
  auto centre = [&](int x, int y, int z) {
    return Eigen::Vector3d(origin_.x() + (x + 0.5) * cell, origin_.y() + (y + 0.5) * cell, origin_.z() + (z + 0.5) * cell);
  };
  // cells within `r` of triangle t's bounding box
  auto forCells = [&](size_t t, double r, auto&& fn) {
    const Eigen::Vector3i& f = faces_[t];
    Eigen::Vector3d lo = vertices_[f[0]].cwiseMin(vertices_[f[1]]).cwiseMin(vertices_[f[2]]);
    Eigen::Vector3d hi = vertices_[f[0]].cwiseMax(vertices_[f[1]]).cwiseMax(vertices_[f[2]]);
    int c0[3], c1[3];
    for (int a = 0; a < 3; ++a) {
      c0[a] = std::max(0, static_cast<int>(std::floor((lo[a] - r - origin_[a]) / cell)));
      c1[a] = std::min(dims_[a] - 1, static_cast<int>(std::floor((hi[a] + r - origin_[a]) / cell)));
    }
    for (int z = c0[2]; z <= c1[2]; ++z)
      for (int y = c0[1]; y <= c1[1]; ++y)
        for (int x = c0[0]; x <= c1[0]; ++x) {
          const Eigen::Vector3d c = centre(x, y, z);
          const double d = (closestPointOnTriangle(c, vertices_[f[0]], vertices_[f[1]], vertices_[f[2]]) - c).norm();
          fn((static_cast<size_t>(z) * dims_[1] + y) * dims_[0] + x, d);
        }
  };
  // pass 1: each near cell's distance to the mesh
  std::vector<float> dc(cells, std::numeric_limits<float>::infinity());
  for (size_t t = 0; t < faces_.size(); ++t) {
    forCells(t, reach, [&](size_t k, double d) {
      if (d < dc[k]) dc[k] = static_cast<float>(d);
    });
  }
  // pass 2: candidates (count, then fill)
  const double slack = 2 * half_diag + 1e-9;
  offsets_.assign(cells + 1, 0);
  auto listed = [&](size_t k, double d) { return dc[k] <= reach && d <= dc[k] + slack; };
  for (size_t t = 0; t < faces_.size(); ++t) {
    forCells(t, reach + slack, [&](size_t k, double d) {
      if (listed(k, d)) ++offsets_[k + 1];
    });
  }
  for (size_t k = 0; k < cells; ++k) offsets_[k + 1] += offsets_[k];
  if (offsets_.back() > std::numeric_limits<uint32_t>::max() / 2) throw std::runtime_error("ClosestPointGrid: too many candidates");
  candidates_.resize(offsets_.back());
  std::vector<uint32_t> fill(offsets_.begin(), offsets_.end() - 1);
  for (size_t t = 0; t < faces_.size(); ++t) {
    forCells(t, reach + slack, [&](size_t k, double d) {
      if (listed(k, d)) candidates_[fill[k]++] = static_cast<uint32_t>(t);
    });
  }
}

ClosestPoint ClosestPointGrid::closestPoint(const Eigen::Vector3f& p, float max_distance, bool* covered) const {
  ClosestPoint best;
  if (covered) *covered = false;
  if (faces_.empty() || !p.allFinite() || !(max_distance > 0)) return best;
  const Eigen::Vector3f g = (p - origin_) * inv_cell_;
  if (!(g.x() >= 0 && g.y() >= 0 && g.z() >= 0 && g.x() < dims_[0] && g.y() < dims_[1] && g.z() < dims_[2])) return best;
  const size_t k = (static_cast<size_t>(g.z()) * dims_[1] + static_cast<size_t>(g.y())) * dims_[0] + static_cast<size_t>(g.x());
  const uint32_t a = offsets_[k], b = offsets_[k + 1];
  if (a == b) return best;
  if (covered) *covered = true;
  const Eigen::Vector3d q = p.cast<double>();
  float radius = max_distance;
  for (uint32_t i = a; i < b; ++i) {
    const Eigen::Vector3i& f = faces_[candidates_[i]];
    // a triangle is no nearer than its plane: most candidates end here (1 µm for float rounding)
    if (std::abs(normals_[candidates_[i]].dot(p - vertices_[f[0]].cast<float>())) >= radius + 1e-6f) continue;
    const Eigen::Vector3d c = closestPointOnTriangle(q, vertices_[f[0]], vertices_[f[1]], vertices_[f[2]]);
    const float d = static_cast<float>((c - q).norm());
    if (d >= radius) continue;
    radius = d;
    best.found = true;
    best.point = c.cast<float>();
    best.distance = d;
    best.geometry = 0;
    best.triangle = face_ids_[candidates_[i]];
    best.normal = normals_[candidates_[i]];
  }
  return best;
}

void ClosestPointGrid::write(BinaryWriter& w) const {
  w.pod(cell_);
  w.pod(inv_cell_);
  w.pod(margin_);
  w.pod(origin_);
  for (int d : dims_) w.pod(d);
  w.vec(vertices_);
  w.vec(faces_);
  w.vec(face_ids_);
  w.vec(normals_);
  w.vec(offsets_);
  w.vec(candidates_);
}

ClosestPointGrid ClosestPointGrid::read(BinaryReader& r) {
  ClosestPointGrid g;
  g.cell_ = r.pod<float>();
  g.inv_cell_ = r.pod<float>();
  g.margin_ = r.pod<float>();
  g.origin_ = r.pod<Eigen::Vector3f>();
  for (int& d : g.dims_) d = r.pod<int>();
  g.vertices_ = r.vec<Eigen::Vector3d>();
  g.faces_ = r.vec<Eigen::Vector3i>();
  g.face_ids_ = r.vec<int>();
  g.normals_ = r.vec<Eigen::Vector3f>();
  g.offsets_ = r.vec<uint32_t>();
  g.candidates_ = r.vec<uint32_t>();
  const size_t cells = static_cast<size_t>(g.dims_[0]) * g.dims_[1] * g.dims_[2];
  if (!g.faces_.empty() && g.offsets_.size() != cells + 1) throw std::runtime_error("closest point grid record: inconsistent");
  for (uint32_t c : g.candidates_)
    if (c >= g.faces_.size()) throw std::runtime_error("closest point grid record: triangle index out of range");
  for (const auto& f : g.faces_)
    if ((f.array() < 0).any() || (f.array() >= static_cast<int>(g.vertices_.size())).any())
      throw std::runtime_error("closest point grid record: vertex index out of range");
  return g;
}

}  // namespace cellsight
