#include "cellsight/common/calibration.hpp"

#include <algorithm>
#include <ctime>
#include <filesystem>
#include <iomanip>
#include <sstream>

#include "cellsight/common/camera_model.hpp"
#include "cellsight/common/file_io.hpp"
#include "cellsight/common/yaml_reader.hpp"

namespace cellsight {

namespace {

TransformCalibration parseTransformCalibration(const YAML::Node& root, const std::string& path) {
  YamlMap m(root, path);
  TransformCalibration c;
  c.parent_frame = m.getString("parent_frame");
  c.child_frame = m.getString("child_frame");
  if (c.parent_frame.empty() || c.parent_frame[0] == '/') {
    m.fail("parent_frame", "must be a non-empty frame id without a leading slash");
  }
  if (c.child_frame.empty() || c.child_frame[0] == '/' || c.child_frame == c.parent_frame) {
    m.fail("child_frame", "must be a frame id without a leading slash, different from the parent");
  }
  c.T_parent_child = m.getPose("transform");
  c.residual_rms = m.getDouble("residual_rms", 0.0);
  c.method = m.getString("method", "");
  c.date = m.getString("date", "");
  m.finish();
  return c;
}

}  // namespace

TransformCalibration loadTransformCalibration(const std::string& path) {
  return parseTransformCalibration(loadYamlFile(path), path);
}

std::string transformCalibrationYaml(const TransformCalibration& c) {
  YAML::Emitter out;
  out.SetDoublePrecision(17);
  out << YAML::BeginMap;
  out << YAML::Key << "parent_frame" << YAML::Value << c.parent_frame;
  out << YAML::Key << "child_frame" << YAML::Value << c.child_frame;
  out << YAML::Key << "transform" << YAML::Value;
  emitPose(out, c.T_parent_child);
  out << YAML::Key << "residual_rms" << YAML::Value << c.residual_rms;
  out << YAML::Key << "method" << YAML::Value << c.method;
  out << YAML::Key << "date" << YAML::Value << c.date;
  out << YAML::EndMap;
  return std::string("# cellsight transform calibration: T_parent_child, metres, quat [x,y,z,w]\n") +
         out.c_str() + "\n";
}

void saveTransformCalibration(const std::string& path, const TransformCalibration& cal) {
  const std::string text = transformCalibrationYaml(cal);
  parseTransformCalibration(YAML::Load(text), path);  // what its loader would refuse is never written
  writeFileAtomic(path, text);
}

CalibrationSet loadCalibrationFolder(const std::string& folder) {
  std::error_code ec;
  std::filesystem::directory_iterator it(folder, ec), end;
  if (ec) throw ConfigError(folder + ": calibration folder cannot be opened");
  std::vector<std::string> files;  // every entry named *.yaml, as readdir listed them
  for (; !ec && it != end; it.increment(ec)) {
    std::string name = it->path().filename().string();
    if (name.size() > 5 && name.substr(name.size() - 5) == ".yaml") files.push_back(name);
  }
  if (ec) throw ConfigError(folder + ": calibration folder cannot be read: " + ec.message());
  std::sort(files.begin(), files.end());
  CalibrationSet set;
  for (const auto& name : files) {
    const std::string path = folder + "/" + name;
    YAML::Node node = loadYamlFile(path);
    if (node.IsMap() && node["parent_frame"]) {
      TransformCalibration cal = loadTransformCalibration(path);
      for (const auto& [other, seen] : set.transforms) {
        if (seen.child_frame == cal.child_frame) {
          throw ConfigError(path + ": frame '" + cal.child_frame + "' is already calibrated in " + other +
                            " (one file per frame: remove or merge one of them)");
        }
      }
      set.transforms.emplace_back(path, std::move(cal));
    } else if (node.IsMap() && node["camera_matrix"]) {
      loadCameraInfoYaml(path);  // validates
      set.camera_files.push_back(path);
    } else {
      throw ConfigError(path + ": neither a transform calibration (parent_frame) nor camera "
                               "intrinsics (camera_matrix)");
    }
  }
  return set;
}

std::string isoDateNow() {
  std::time_t t = std::time(nullptr);
  std::tm tm{};
  gmtime_r(&t, &tm);
  std::ostringstream s;
  s << std::put_time(&tm, "%Y-%m-%dT%H:%M:%SZ");
  return s.str();
}

}  // namespace cellsight
