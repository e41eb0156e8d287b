#include "cellsight/sim/ground_truth.hpp"

#include <sys/stat.h>
#include <unistd.h>

#include <cerrno>
#include <cstring>
#include <filesystem>
#include <nlohmann/json.hpp>
#include <stdexcept>

#include "cellsight/common/calibration.hpp"
#include "cellsight/common/file_io.hpp"

namespace cellsight {

namespace {
nlohmann::json poseJson(const Eigen::Isometry3d& T) {
  const Eigen::Quaterniond q(T.linear());
  return {{"xyz", {T.translation().x(), T.translation().y(), T.translation().z()}},
          {"quat", {q.x(), q.y(), q.z(), q.w()}}};
}
}  // namespace

std::string sceneTruthJson(const Scene& s) {
  nlohmann::json j;
  j["scene"] = s.name;
  j["scene_file"] = s.file;
  j["units"] = "metres, radians; quaternions [x, y, z, w]";
  j["base_frame"] = s.base_frame;
  j["workspace"] = {{"min", {s.workspace.min().x(), s.workspace.min().y(), s.workspace.min().z()}},
                    {"max", {s.workspace.max().x(), s.workspace.max().y(), s.workspace.max().z()}}};
  j["objects"] = nlohmann::json::array();
  for (const auto& o : s.objects) {
    j["objects"].push_back({{"name", o.name},
                            {"model", o.model},
                            {"mesh", o.info.mesh_file},
                            {"T_base_object", poseJson(o.T_base_object)}});
  }
  j["fixtures"] = nlohmann::json::array();
  for (const auto& f : s.fixtures) {
    j["fixtures"].push_back({{"id", f.id},
                             {"payload", f.payload},
                             {"code_size", f.code_size},
                             {"T_base_fixture", poseJson(f.T_base_fixture)}});
  }
  j["T_base_scanner_camera"] = poseJson(s.scanner_camera.T_base_camera);
  j["T_base_fixture_camera"] = poseJson(s.fixture_camera.T_base_camera);
  j["T_flange_laser"] = poseJson(s.laser.T_flange_laser);
  return j.dump(2) + "\n";
}

void writeSceneTruth(const Scene& s, const std::string& dir) {
  // The calibration folder appears complete or not at all: written aside, then renamed.
  makeDirs(dir);
  const std::string final_dir = dir + "/calibration";
  const std::string tmp_dir = dir + "/.calibration.tmp." + std::to_string(::getpid());
  makeDirs(tmp_dir);
  writeFileAtomic(dir + "/scene_truth.json", sceneTruthJson(s));
  saveCameraInfoYaml(tmp_dir + "/scanner_camera.yaml", s.scanner_camera.intrinsics);
  saveCameraInfoYaml(tmp_dir + "/fixture_camera.yaml", s.fixture_camera.intrinsics);
  const std::string date = isoDateNow();
  auto save = [&](const std::string& name, const std::string& parent, const std::string& child,
                  const Eigen::Isometry3d& T) {
    TransformCalibration c;
    c.parent_frame = parent;
    c.child_frame = child;
    c.T_parent_child = T;
    c.method = "simulator ground truth (" + s.file + ")";
    c.date = date;
    saveTransformCalibration(tmp_dir + "/" + name, c);
  };
  save("scanner_camera_pose.yaml", s.base_frame, s.scanner_camera.frame_id,
       s.scanner_camera.T_base_camera);
  save("fixture_camera_pose.yaml", s.base_frame, s.fixture_camera.frame_id,
       s.fixture_camera.T_base_camera);
  save("laser.yaml", s.flange_frame, s.laser_frame, s.laser.T_flange_laser);
  const std::string old_dir = dir + "/.calibration.old." + std::to_string(::getpid());
  const bool had_old = ::rename(final_dir.c_str(), old_dir.c_str()) == 0;
  if (::rename(tmp_dir.c_str(), final_dir.c_str()) != 0) {
    throw std::runtime_error(final_dir + ": cannot move the new calibration in place: " +
                             std::strerror(errno));
  }
  if (had_old) removeTree(old_dir);
}

std::string frameTruthJsonLine(int index, int64_t stamp_ns, const Eigen::Isometry3d& T_base_flange,
                               const Plane& plane) {
  nlohmann::json j = {{"frame", index},
                      {"stamp_ns", stamp_ns},
                      {"T_base_flange", poseJson(T_base_flange)},
                      {"plane_camera", {{"n", {plane.n.x(), plane.n.y(), plane.n.z()}}, {"d", plane.d}}}};
  return j.dump() + "\n";
}

}  // namespace cellsight
