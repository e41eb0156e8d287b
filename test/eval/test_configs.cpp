// Every shipped YAML loads; broken scenes are rejected with the file and the field named.
#include <gtest/gtest.h>

#include "cellsight/fixtures/fixture_registry.hpp"

#include <algorithm>
#include <filesystem>

#include "cellsight/common/calibration.hpp"
#include "cellsight/common/file_io.hpp"
#include "cellsight/scanner/scanner_config.hpp"
#include "cellsight/sim/scene.hpp"
#include "cellsight/common/trajectory.hpp"
#include "cellsight/common/yaml_reader.hpp"
#include "test_helpers.hpp"

using namespace cellsight;

namespace {
const std::string kConfig = std::string(CELLSIGHT_SOURCE_DIR) + "/config";

std::vector<std::string> listDir(const std::string& dir) {
  std::vector<std::string> out;
  std::error_code ec;
  for (const auto& e : std::filesystem::directory_iterator(dir, ec)) {
    const std::string name = e.path().filename().string();
    if (name[0] != '.') out.push_back(name);
  }
  std::sort(out.begin(), out.end());
  return out;
}

std::string sceneError(const std::string& yaml_text) {
  const std::string dir = cellsight_test::tempDir();
  cellsight_test::writeText(dir + "/scene.yaml", yaml_text);
  SceneLoadOptions opt;
  opt.model_paths = {kConfig + "/models", dir};
  return cellsight_test::errorOf([&] { loadScene(dir + "/scene.yaml", opt); });
}

const char* kGoodScene = R"(
name: t
workspace: {min: [0.35, -0.125, 0.0], max: [0.69, 0.125, 0.10]}
objects:
  - {name: a, model: housing, pose: {xyz: [0.5, 0, 0], rpy: [0, 0, 0]}}
scanner_camera:
  resolution: [640, 480]
  focal_px: [800, 800]
  pose: {xyz: [0.52, 0.0, 0.62], rpy: [3.14159265358979, 0.0, 0.0]}
laser:
  pose_in_flange: {xyz: [0.06, 0.0, 0.04], rpy: [0, 0, 0]}
)";
}  // namespace

TEST(ShippedConfig, EveryModelSceneAndTrajectoryLoads) {
  const auto models = listDir(kConfig + "/models");
  EXPECT_GE(models.size(), 4u);
  for (const auto& m : models) {
    const ModelInfo info = loadModelInfo(kConfig + "/models/" + m + "/model.yaml");
    EXPECT_EQ(info.id, m);
    EXPECT_TRUE(checkMesh(loadValidMesh(info.mesh_file)).ok());
  }
  for (const auto& s : listDir(kConfig + "/scenes")) {
    const Scene scene = loadScene(kConfig + "/scenes/" + s);
    EXPECT_FALSE(scene.objects.empty()) << s;
  }
  const auto traj = loadTrajectories(kConfig + "/trajectories.yaml");
  EXPECT_GT(traj.at("demo_sweep").poses.size(), 100u);
}

TEST(ShippedConfig, DemoSceneMatchesTheThesisWorkspace) {
  const Scene s = loadScene(kConfig + "/scenes/demo.yaml");
  EXPECT_NEAR(s.workspace.sizes().x(), 0.34, 1e-9);
  EXPECT_NEAR(s.workspace.sizes().y(), 0.25, 1e-9);
  EXPECT_NEAR(s.workspace.sizes().z(), 0.10, 1e-9);
  EXPECT_EQ(s.scanner_camera.intrinsics.width, 1920);
  EXPECT_EQ(s.scanner_camera.intrinsics.height, 1080);
  // fixtures A and B with one code each, C with three; every code known to the registry
  EXPECT_EQ(s.fixtures.size(), 5u);
  const FixtureRegistry reg = loadFixtureRegistry(kConfig + "/fixtures.yaml");
  for (const auto& f : s.fixtures) EXPECT_NE(reg.find(f.payload), nullptr) << f.payload;
  int parts = 0;
  bool sphere = false;
  for (const auto& o : s.objects) {
    if (o.model == "sphere25") sphere = true; else ++parts;
    EXPECT_TRUE(s.workspace.contains(o.T_base_object.translation())) << o.name;
  }
  EXPECT_TRUE(sphere);
  EXPECT_GE(parts, 3);
  EXPECT_LE(parts, 5);
}

TEST(ShippedConfig, ScannerSettingsLoadAndTypoIsNamed) {
  const ScannerSettings s = loadScannerSettings(kConfig + "/scanner.yaml");
  EXPECT_TRUE(s.has_workspace);
  EXPECT_EQ(s.line.smoothing_degree, 2);
  EXPECT_GT(s.laser_fan_angle, 0.5) << "the demo projector's fan bounds the light sweep";
  const std::string dir = cellsight_test::tempDir();
  cellsight_test::writeText(dir + "/s.yaml", "line: {estimater: centroid}\n");
  const std::string msg = cellsight_test::errorOf([&] { loadScannerSettings(dir + "/s.yaml"); });
  EXPECT_NE(msg.find("line.estimater: unknown key"), std::string::npos) << msg;
}

TEST(ShippedConfig, ScannerSettingsRefuseValuesThatPassAsNumbers) {
  const std::string dir = cellsight_test::tempDir();
  for (const auto& [text, key] : std::vector<std::pair<std::string, std::string>>{
           {"outlier_k: -5\n", "outlier_k"}, {"normal_k: 1\n", "normal_k"}, {"outlier_std: .nan\n", "outlier_std"},
           {"line: {max_run: 0}\n", "line.max_run"}, {"line: {min_contrast: -1}\n", "line.min_contrast"},
           {"laser_fan_angle: 4\n", "laser_fan_angle"}}) {
    cellsight_test::writeText(dir + "/s.yaml", text);
    const std::string msg = cellsight_test::errorOf([&] { loadScannerSettings(dir + "/s.yaml"); });
    EXPECT_NE(msg.find(key + ": must be"), std::string::npos) << text << " -> " << msg;
  }
  cellsight_test::writeText(dir + "/s.yaml", "normal_k: 0\noutlier_k: 0\n");  // both switched off: fine
  EXPECT_EQ(cellsight_test::errorOf([&] { loadScannerSettings(dir + "/s.yaml"); }), "");
}

TEST(BadConfig, GoodBaseSceneLoads) { EXPECT_EQ(sceneError(kGoodScene), ""); }

TEST(BadConfig, UnknownKeyIsNamed) {
  std::string text = kGoodScene;
  text += "lasr: {}\n";
  EXPECT_NE(sceneError(text).find("scene.yaml: lasr: unknown key"), std::string::npos) << sceneError(text);
  std::string nested = kGoodScene;
  nested.replace(nested.find("focal_px"), 8, "focal_pz");
  EXPECT_NE(sceneError(nested).find("scanner_camera.focal_px: required key is missing"), std::string::npos)
      << sceneError(nested);
}

// a resolution beyond int (found by fuzz_yaml: the cast was undefined) or not whole pixels
TEST(BadConfig, ResolutionOutOfRangeIsNamed) {
  for (const char* bad : {"[1.4e56, 480]", "[640, 0]", "[640.5, 480]", "[40000, 480]"}) {
    std::string text = kGoodScene;
    text.replace(text.find("[640, 480]"), 10, bad);
    EXPECT_NE(sceneError(text).find("resolution: must be two whole numbers of pixels"), std::string::npos)
        << bad << ": " << sceneError(text);
  }
}

TEST(BadConfig, MalformedYamlIsNamed) {
  EXPECT_NE(sceneError("name: [unclosed\n").find("YAML syntax error"), std::string::npos);
  EXPECT_NE(sceneError("- just\n- a list\n").find("must be a mapping"), std::string::npos);
}

TEST(BadConfig, MissingModelAndMeshAreNamed) {
  std::string text = kGoodScene;
  text.replace(text.find("model: housing"), 14, "model: nothere");
  EXPECT_NE(sceneError(text).find("objects[0].model: no model 'nothere'"), std::string::npos) << sceneError(text);
  const std::string dir = cellsight_test::tempDir();
  cellsight::makeDirs(dir + "/ghost");
  cellsight_test::writeText(dir + "/ghost/model.yaml", "id: ghost\nmesh: ghost.ply\n");
  EXPECT_NE(cellsight_test::errorOf([&] { loadModelInfo(dir + "/ghost/model.yaml"); }).find("model.yaml: mesh: file"),
            std::string::npos);
}

TEST(BadConfig, NonManifoldMeshIsNamed) {
  const std::string dir = cellsight_test::tempDir();
  cellsight::makeDirs(dir + "/broken/");
  TriangleMesh fan;
  fan.vertices = {{0, 0, 0}, {0.01f, 0, 0}, {0, 0.01f, 0}, {0, -0.01f, 0}, {0, 0, 0.01f}};
  fan.faces = {{0, 1, 2}, {1, 0, 3}, {0, 1, 4}};
  saveMeshPly(dir + "/broken/mesh.ply", fan);
  cellsight_test::writeText(dir + "/broken/model.yaml", "id: broken\nmesh: mesh.ply\n");
  std::string text = kGoodScene;
  text.replace(text.find("model: housing"), 14, "model: broken");
  cellsight_test::writeText(dir + "/scene.yaml", text);
  SceneLoadOptions opt;
  opt.model_paths = {dir};
  try {
    loadScene(dir + "/scene.yaml", opt);
    FAIL();
  } catch (const ConfigError& e) {
    const std::string msg = e.what();
    EXPECT_NE(msg.find("object 'a'"), std::string::npos) << msg;
    EXPECT_NE(msg.find("non-manifold"), std::string::npos) << msg;
  }
}

TEST(BadConfig, CameraThatSeesNothingIsRejected) {
  std::string text = kGoodScene;
  text.replace(text.find("rpy: [3.14159265358979, 0.0, 0.0]"), 33, "rpy: [0.0, 0.0, 0.0]");  // looks up
  EXPECT_NE(sceneError(text).find("scanner_camera.pose: the camera sees none of the workspace"),
            std::string::npos) << sceneError(text);
}

TEST(BadConfig, OutOfRangeValuesAreNamed) {
  std::string text = kGoodScene;
  text.replace(text.find("pose_in_flange"), 14, "fan_angle: -1\n  pose_in_flange");
  EXPECT_NE(sceneError(text).find("laser.fan_angle: must lie in"), std::string::npos) << sceneError(text);
}
