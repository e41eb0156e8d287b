// Loads every YAML under a config folder with its strict loader (scenes, models, trajectories,
// calibrations) and reports each problem with file and key. Exit 0 only if all are valid.
// Usage: cellsight_validate_config <config folder | file.yaml>...   (--help for details)
// Folders are searched recursively for *.yaml, in sorted order (names compared bytewise); a path
// that does not exist is a usage error (CLI11, non-zero exit); no .yaml found: exit 2.
#include <algorithm>
#include <filesystem>
#include <functional>
#include <iostream>
#include <string>
#include <vector>

#include "cellsight/common/calibration.hpp"
#include "cellsight/common/camera_model.hpp"
#include "cellsight/localization/clustering.hpp"
#include "cellsight/localization/model_matching.hpp"
#include "cellsight/scanner/scanner_config.hpp"
#include "cellsight/sim/scene.hpp"
#include "cellsight/common/trajectory.hpp"
#include "cellsight/common/file_io.hpp"
#include "cellsight/common/yaml_reader.hpp"
#include "cellsight/fixtures/fixture_registry.hpp"
#include "cellsight/planning/grasp_planner.hpp"
#include "cli_args.hpp"

namespace {

/// *.yaml files under `path` (a file or a folder, searched recursively; links followed), each
/// folder's entries in sorted order; what cannot be read is skipped.
void collect(const std::string& path, std::vector<std::string>& out) {
  namespace fs = std::filesystem;
  std::error_code ec;
  const fs::file_status st = fs::status(path, ec);
  if (ec || !fs::exists(st)) return;
  if (!fs::is_directory(st)) {
    if (path.size() > 5 && path.substr(path.size() - 5) == ".yaml") out.push_back(path);
    return;
  }
  std::vector<std::string> names;
  for (fs::directory_iterator it(path, ec), end; !ec && it != end; it.increment(ec))
    names.push_back(it->path().filename().string());
  std::sort(names.begin(), names.end());
  for (const auto& name : names) collect(path + "/" + name, out);
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
  if (node.IsMap() && node["fixtures"] && node["fixtures"].IsSequence() &&
      (node["fixtures"].size() == 0 || node["fixtures"][0]["codes"])) {
    const auto r = cellsight::loadFixtureRegistry(f);
    size_t codes = 0;
    for (const auto& t : r.fixtures) codes += t.codes.size();
    return "fixture registry (" + std::to_string(r.fixtures.size()) + " fixture types, " + std::to_string(codes) + " codes)";
  }
  if (node.IsMap() && node["seeds"]) {  // the held-out seeds of random cells
    cellsight::YamlMap m(node, f);
    const std::string base = cellsight::resolveRelative(f, m.getString("base"));
    cellsight::loadScene(base);
    std::vector<int> seeds;
    for (const auto& s : m.raw("seeds")) seeds.push_back(s.as<int>());
    std::sort(seeds.begin(), seeds.end());
    if (seeds.empty() || std::adjacent_find(seeds.begin(), seeds.end()) != seeds.end())
      m.fail("seeds", "must be a non-empty list of distinct integers");
    m.finish();
    return std::to_string(seeds.size()) + " held-out seeds on " + base;
  }
  if (node.IsMap() && node["base_model"]) {
    const auto a = cellsight::loadAssemblyConfig(f);
    return "assembly: base '" + a.base_model + "', " + std::to_string(a.order.size()) + " parts placed";
  }
  if (f.size() >= 10 && f.substr(f.size() - 10) == "model.yaml") {
    return "model '" + cellsight::loadModelInfo(f).id + "'";
  }
  throw cellsight::ConfigError(f + ": unknown kind of configuration file");
}

int main(int argc, char** argv) {
  std::vector<std::string> paths;
  CLI::App app("Loads every YAML under the given folders (recursively) and files with its strict loader (scenes, "
               "models, trajectories, calibrations, settings) and reports each problem with file and key. Exit 0 "
               "only if all are valid.",
               "cellsight_validate_config");
  app.add_option("paths", paths, "config folders and/or .yaml files")->required()->check(CLI::ExistingPath);
  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  std::vector<std::string> files;
  for (const auto& p : paths) collect(p, files);
  if (files.empty()) {
    std::cerr << "no .yaml files found\n";
    return 2;
  }
  int bad = 0;
  for (const auto& f : files) {
    try {
      const std::string what = validateFile(f);  // first: "ok" is printed only for a file that loaded
      std::cout << "ok    " << f << ": " << what << "\n";
    } catch (const std::exception& e) {
      std::cout << "ERROR " << e.what() << "\n";
      ++bad;
    }
  }
  std::cout << files.size() - bad << " valid, " << bad << " invalid\n";
  return bad == 0 ? 0 : 1;
}
