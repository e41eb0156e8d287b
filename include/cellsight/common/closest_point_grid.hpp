// Exact closest-point queries on a small triangle mesh through a grid of candidate triangles.
// Each cell near the surface lists the triangles that can be closest to *any* point inside it:
// those within d_c + (cell diagonal) of the cell centre, d_c being the centre's distance to the
// mesh (for q in the cell the closest triangle t* has dist(c, t*) <= dist(q, t*) + δ <=
// d_c + 2δ, δ = half the diagonal). A query is one cell lookup and a few triangle projections
// instead of a BVH traversal: the matcher's final alignment (6 polish iterations over ~2 000
// points) took 0.8–3.3 ms per view with it, 7.5–12.5 ms with Embree's point query
// (RayCaster::closestPoint; docs/localization.md). Points in cells without a
// list lie farther than `margin` from the mesh: the query says so and callers that need
// farther answers fall back to the RayCaster.
#pragma once
#include <Eigen/Core>
#include <cstdint>
#include <vector>

#include "cellsight/common/mesh.hpp"
#include "cellsight/common/raycaster.hpp"

namespace cellsight {

class BinaryWriter;
class BinaryReader;

class ClosestPointGrid {
 public:
  ClosestPointGrid() = default;
  /// `cell` and `margin` in metres; the cell grows if the mesh's box would need more than
  /// `max_cells` cells.
  ClosestPointGrid(const TriangleMesh& mesh, float cell, float margin, size_t max_cells = 8u << 20);

  bool empty() const { return faces_.empty(); }
  float margin() const { return margin_; }

  /// The closest point of the mesh to p if it is nearer than max_distance (found, as
  /// RayCaster::closestPoint). *covered = false when p lies in no listed cell: then nothing is
  /// within `margin` of p, and the answer is exact only if max_distance <= margin.
  ClosestPoint closestPoint(const Eigen::Vector3f& p, float max_distance, bool* covered = nullptr) const;

  /// The grid as a flat record (model-preparation cache) and back.
  void write(BinaryWriter& w) const;
  static ClosestPointGrid read(BinaryReader& r);

 private:
  float cell_ = 0, inv_cell_ = 0, margin_ = 0;
  Eigen::Vector3f origin_ = Eigen::Vector3f::Zero();
  int dims_[3] = {0, 0, 0};
  std::vector<Eigen::Vector3d> vertices_;
  std::vector<Eigen::Vector3i> faces_;  // non-degenerate faces
  std::vector<int> face_ids_;           // their index in the mesh
  std::vector<Eigen::Vector3f> normals_;
  std::vector<uint32_t> offsets_;     // per cell (+1): range in candidates_
  std::vector<uint32_t> candidates_;  // triangle indices
};

}  // namespace cellsight
