// Loads every YAML under a config folder with its strict loader (scenes, models, trajectories,
// calibrations) and reports each problem with file and key. Exit 0 only if all are valid.
// Usage: cellsight_validate_config <config folder> | <file.yaml>...
#include <dirent.h>
#include <sys/stat.h>

#include <functional>
#include <iostream>
#include <string>
#include <vector>

#include "cellsight/calibration.hpp"
#include "cellsight/camera_model.hpp"
#include "cellsight/clustering.hpp"
#include "cellsight/model_matching.hpp"
#include "cellsight/scanner_config.hpp"
#include "cellsight/scene.hpp"
#include "cellsight/trajectory.hpp"
#include "cellsight/yaml_reader.hpp"

namespace {

void collect(const std::string& path, std::vector<std::string>& out) {
  struct stat st {};
  if (::stat(path.c_str(), &st) != 0) return;
  if (!S_ISDIR(st.st_mode)) {
    if (path.size() > 5 && path.substr(path.size() - 5) == ".yaml") out.push_back(path);
    return;
  }
  DIR* dir = opendir(path.c_str());
  if (!dir) return;
  while (dirent* e = readdir(dir)) {
    const std::string name = e->d_name;
    if (name == "." || name == "..") continue;
    collect(path + "/" + name, out);
  }
  closedir(dir);
}

}  // namespace

/// Validates one file by its kind; returns a description of what it is.
std::string validateFile(const std::string& f) {
  const YAML::Node node = cellsight::loadYamlFile(f);
  if (node.IsMap() && node["scanner_camera"]) {
    const auto s = cellsight::loadScene(f);
    return "scene '" + s.name + "' (" + std::to_string(s.objects.size()) + " objects)";
  }
  if (node.IsMap() && node["trajectories"]) {
    return std::to_string(cellsight::loadTrajectories(f).size()) + " trajectories";
  }
  if (node.IsMap() && node["camera_matrix"]) {
    cellsight::loadCameraInfoYaml(f);
    return "camera intrinsics";
  }
  if (node.IsMap() && node["parent_frame"]) {
    const auto c = cellsight::loadTransformCalibration(f);
    return "transform " + c.parent_frame + " -> " + c.child_frame;
  }
  if (node.IsMap() && node["cluster_tolerance"]) {
    cellsight::loadClusteringConfig(f);
    return "clustering settings";
  }
  if (node.IsMap() && (node["ppf_sampling"] || node["fitness_radius"] || node["coarse"])) {
    cellsight::loadMatchingConfig(f);
    return "matching settings";
  }
  if (node.IsMap() && (node["line"] || node["triangulation"] || node["outlier_k"])) {
    cellsight::loadScannerSettings(f);
    return "scanner settings";
  }
  if (f.size() >= 10 && f.substr(f.size() - 10) == "model.yaml") {
    return "model '" + cellsight::loadModelInfo(f).id + "'";
  }
  throw cellsight::ConfigError(f + ": unknown kind of configuration file");
}

int main(int argc, char** argv) {
  if (argc < 2) {
    std::cerr << "usage: cellsight_validate_config <config folder | file.yaml>...\n";
    return 2;
  }
  std::vector<std::string> files;
  for (int i = 1; i < argc; ++i) collect(argv[i], files);
  if (files.empty()) {
    std::cerr << "no .yaml files found\n";
    return 2;
  }
  int bad = 0;
  for (const auto& f : files) {
    try {
      std::cout << "ok    " << f << ": " << validateFile(f) << "\n";
    } catch (const std::exception& e) {
      std::cout << "ERROR " << e.what() << "\n";
      ++bad;
    }
  }
  std::cout << files.size() - bad << " valid, " << bad << " invalid\n";
  return bad == 0 ? 0 : 1;
}
