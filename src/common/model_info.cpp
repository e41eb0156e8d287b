#include "cellsight/common/model_info.hpp"

#include <sys/stat.h>

#include "cellsight/common/file_io.hpp"
#include "cellsight/common/yaml_reader.hpp"

namespace cellsight {

namespace {

bool fileExists(const std::string& p) {
  struct stat st {};
  return ::stat(p.c_str(), &st) == 0;
}

Eigen::Vector3d unitVector(const YamlMap& m, const std::string& key, const Eigen::Vector3d& def) {
  Eigen::Vector3d v = m.getVector3(key, def);
  if (v.norm() < 1e-9) m.fail(key, "must be a non-zero vector");
  return v.normalized();
}

}  // namespace

ModelInfo loadModelInfo(const std::string& path) {
  YamlMap m(loadYamlFile(path), path);
  ModelInfo info;
  info.id = m.getString("id");
  info.description = m.getString("description", "");
  info.mesh_file = resolveRelative(path, m.getString("mesh"));
  if (!fileExists(info.mesh_file)) m.fail("mesh", "file " + info.mesh_file + " does not exist");
  info.T_model_grasp = m.getPose("grasp_frame", Eigen::Isometry3d::Identity());
  info.T_0i = m.getPose("T_0i", Eigen::Isometry3d::Identity());
  info.assembly_direction = unitVector(m, "assembly_direction", -Eigen::Vector3d::UnitZ());
  info.base_part = m.getBool("base_part", false);
  if (m.has("symmetry")) {
    YamlMap s = m.getMap("symmetry");
    const std::string type = s.getString("type");
    if (type == "none") {
      info.symmetry.type = Symmetry::Type::kNone;
    } else if (type == "axial") {
      info.symmetry.type = Symmetry::Type::kAxial;
    } else if (type == "discrete") {
      info.symmetry.type = Symmetry::Type::kDiscrete;
      info.symmetry.order = s.getInt("order");
      if (info.symmetry.order < 2) s.fail("order", "discrete symmetry needs order >= 2");
    } else if (type == "spherical") {
      info.symmetry.type = Symmetry::Type::kSpherical;
    } else {
      s.fail("type", "must be none, axial, discrete or spherical (got '" + type + "')");
    }
    info.symmetry.axis = unitVector(s, "axis", Eigen::Vector3d::UnitZ());
    s.finish();
  }
  m.finish();
  return info;
}

}  // namespace cellsight
