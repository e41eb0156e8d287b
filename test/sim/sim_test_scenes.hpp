// Small synthetic scenes for the tests of the simulator and of what is measured on it.
#pragma once
#include "cellsight/common/mesh.hpp"
#include "cellsight/sim/scene.hpp"
#include "test_helpers.hpp"

namespace cellsight_test {

/// A table at z = 0 seen by a 640×480 camera 0.5 m above, with mild distortion; no objects.
inline cellsight::Scene planeScene() {
  cellsight::Scene s;
  s.name = "test";
  s.workspace = Eigen::AlignedBox3d(Eigen::Vector3d(-0.1, -0.1, 0), Eigen::Vector3d(0.1, 0.1, 0.1));
  s.table.center = {0, 0};
  s.table.size = {1.0, 1.0};
  s.table.reflectivity = 1.0;
  auto& c = s.scanner_camera;
  c.intrinsics = {"test_camera", 640, 480, 800, 800, 319.5, 239.5, {-0.05, 0.02, 0.0002, -0.0001, 0}};
  c.frame_id = "camera";
  c.T_base_camera = lookDown({0, 0, 0.5});
  s.fixture_camera = c;
  s.laser.line_width = 1.5e-3;
  s.laser.brightness = 200;
  s.laser.fan_angle = 1.2;
  s.noise.enabled = false;
  return s;
}

/// Adds an object with the given mesh (written to `dir`) to the scene.
inline void addObject(cellsight::Scene& s, const std::string& dir, const std::string& name,
                      const cellsight::TriangleMesh& mesh, const Eigen::Isometry3d& pose) {
  cellsight::SceneObject o;
  o.name = name;
  o.model = name;
  o.info.id = name;
  o.info.mesh_file = dir + "/" + name + ".ply";
  cellsight::saveMeshPly(o.info.mesh_file, mesh);
  o.T_base_object = pose;
  o.reflectivity = 1.0;
  s.objects.push_back(o);
}

/// Laser frame whose sheet contains `emitter` and the line through `target` along x.
inline Eigen::Isometry3d laserAiming(const Eigen::Vector3d& emitter, const Eigen::Vector3d& target) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  const Eigen::Vector3d z = (target - emitter).normalized();
  const Eigen::Vector3d x = Eigen::Vector3d::UnitX();
  const Eigen::Vector3d y = z.cross(x).normalized();
  T.linear().col(0) = y.cross(z);
  T.linear().col(1) = y;
  T.linear().col(2) = z;
  T.translation() = emitter;
  return T;
}

}  // namespace cellsight_test
