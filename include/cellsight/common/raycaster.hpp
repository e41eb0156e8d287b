// Ray casting against triangle meshes (Embree 3 behind a pimpl: no Embree header leaks out).
#pragma once
#include <Eigen/Core>
#include <Eigen/Geometry>
#include <limits>
#include <memory>

#include "cellsight/common/mesh.hpp"

namespace cellsight {

struct RayHit {
  bool hit = false;
  float t = std::numeric_limits<float>::infinity();  ///< distance along the unit direction
  int geometry = -1;                                  ///< id returned by addMesh
  int triangle = -1;
  Eigen::Vector3f normal = Eigen::Vector3f::Zero();  ///< unit outward normal of the triangle
};

struct ClosestPoint {
  bool found = false;
  Eigen::Vector3f point = Eigen::Vector3f::Zero();   ///< on the surface
  Eigen::Vector3f normal = Eigen::Vector3f::Zero();  ///< unit outward normal of its triangle
  float distance = std::numeric_limits<float>::infinity();
  int geometry = -1, triangle = -1;
};

class RayCaster {
 public:
  RayCaster();
  ~RayCaster();
  RayCaster(const RayCaster&) = delete;
  RayCaster& operator=(const RayCaster&) = delete;

  /// Adds a mesh placed at T (mesh frame → world). Returns its geometry id (0, 1, 2, ...).
  int addMesh(const TriangleMesh& mesh, const Eigen::Isometry3d& T);
  /// Builds the acceleration structure; call once after all addMesh calls.
  void commit();

  /// First hit along origin + t·dir, t in (t_near, t_far); `dir` must be unit length.
  RayHit intersect(const Eigen::Vector3f& origin, const Eigen::Vector3f& dir, float t_near = 0.f,
                   float t_far = std::numeric_limits<float>::infinity()) const;
  /// True if anything lies on the segment (t_near, t_far).
  bool occluded(const Eigen::Vector3f& origin, const Eigen::Vector3f& dir, float t_near,
                float t_far) const;
  /// Closest point of all meshes to p within max_distance (Embree point query over the BVH);
  /// found = false when nothing lies that close.
  ClosestPoint closestPoint(const Eigen::Vector3f& p, float max_distance) const;

 private:
  struct Impl;
  std::unique_ptr<Impl> impl_;
};

}  // namespace cellsight
