// Part model metadata (config/models/<id>/model.yaml): mesh, grasp frame, place in the assembly,
// symmetry. Shared by the simulator, localisation and planning. Units: metres, radians.
#pragma once
#include <Eigen/Geometry>
#include <string>

namespace cellsight {

struct Symmetry {
  enum class Type { kNone, kAxial, kDiscrete, kSpherical } type = Type::kNone;
  Eigen::Vector3d axis = Eigen::Vector3d::UnitZ();  ///< in the model frame
  int order = 1;                                    ///< discrete: rotations by 2π/order
  // spherical: any rotation about the model's centroid leaves it unchanged (axis unused)
};

/// Part model metadata; the model frame is the mesh frame.
struct ModelInfo {
  std::string id;
  std::string mesh_file;  ///< absolute after loading
  std::string description;
  Eigen::Isometry3d T_model_grasp = Eigen::Isometry3d::Identity();  ///< z normal to gripped face
  Eigen::Isometry3d T_0i = Eigen::Isometry3d::Identity();  ///< pose in the assembly, base part
  Eigen::Vector3d assembly_direction = -Eigen::Vector3d::UnitZ();  ///< v_i, assembly frame
  Symmetry symmetry;
  bool base_part = false;
};

/// Loads `<folder>/model.yaml`; the mesh path is resolved relative to it.
ModelInfo loadModelInfo(const std::string& model_yaml);

}  // namespace cellsight
