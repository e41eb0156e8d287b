// Scanner calibration from files (each result written atomically; residuals reported as JSON):
//   intrinsics  --images <dir or files...> --board 9x6 --square 0.025 [--model k1|full]
//               [--fix-aspect] [--name scanner_camera] --out camera.yaml
//   extrinsics  --camera camera.yaml --image pattern.png --board 9x6 --square 0.025
//               --taught taught.yaml [--parent base_link] [--child scanner_camera_optical] --out pose.yaml
//               taught.yaml: {origin: [x,y,z], on_x: [x,y,z], in_xy: [x,y,z]} (metres, parent frame):
//               the pattern's first inner corner, a point on its row direction, a point on its plane
//   laser       --camera camera.yaml --camera-pose pose.yaml --observations obs.yaml
//               [--method lsq|three_point] [--flange flange] [--child laser] --out laser.yaml
//               obs.yaml: {observations: [{image: f.png, flange_pose: {xyz, rpy|quat}, plane_z: 0,
//               block_z: 0.02}, ...]} (image paths relative to obs.yaml)
#include <algorithm>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "cellsight/calibrate.hpp"
#include "cellsight/calibration.hpp"
#include "cellsight/file_io.hpp"
#include "cellsight/yaml_reader.hpp"

using namespace cellsight;

namespace {

struct Args {
  std::map<std::string, std::vector<std::string>> kv;
  std::string get(const std::string& k, const std::string& def = "") const {
    auto it = kv.find(k);
    return it == kv.end() || it->second.empty() ? def : it->second.front();
  }
  std::string need(const std::string& k) const {
    const std::string v = get(k);
    if (v.empty()) throw std::invalid_argument("--" + k + " is required");
    return v;
  }
  bool flag(const std::string& k) const { return kv.count(k) > 0; }
};

Args parse(int argc, char** argv) {
  Args a;
  std::string key;
  for (int i = 2; i < argc; ++i) {
    const std::string s = argv[i];
    if (s.rfind("--", 0) == 0) {
      key = s.substr(2);
      a.kv[key];
    } else if (!key.empty()) {
      a.kv[key].push_back(s);
    } else {
      throw std::invalid_argument("unexpected argument '" + s + "'");
    }
  }
  return a;
}

ChessboardSpec board(const Args& a) {
  ChessboardSpec b;
  const std::string s = a.need("board");
  const auto x = s.find('x');
  if (x == std::string::npos) throw std::invalid_argument("--board must look like 9x6 (inner corners)");
  b.inner_corners = cv::Size(std::stoi(s.substr(0, x)), std::stoi(s.substr(x + 1)));
  b.square_size = std::stod(a.need("square"));
  if (b.square_size <= 0) throw std::invalid_argument("--square must be > 0 (metres)");
  return b;
}

void saveTransform(const std::string& path, const std::string& parent, const std::string& child,
                   const Eigen::Isometry3d& T, double residual, const std::string& method) {
  TransformCalibration c;
  c.parent_frame = parent;
  c.child_frame = child;
  c.T_parent_child = T;
  c.residual_rms = residual;
  c.method = method;
  c.date = isoDateNow();
  saveTransformCalibration(path, c);
}

int intrinsics(const Args& a) {
  const auto files = listImages(a.kv.count("images") ? a.kv.at("images") : std::vector<std::string>{});
  if (files.empty()) throw std::invalid_argument("--images: no image files given or found");
  const DistortionModel model = parseDistortionModel(a.get("model", "full"));
  IntrinsicsResult r = calibrateIntrinsics(files, board(a), model, a.flag("fix-aspect"));
  r.camera.camera_name = a.get("name", "scanner_camera");
  const std::string out = a.need("out");
  saveCameraInfoYaml(out, r.camera);
  nlohmann::json j = {{"output", out},
                      {"model", a.get("model", "full")},
                      {"rms_px", r.rms_px},
                      {"views_used", r.used.size()},
                      {"views_rejected", r.rejected},
                      {"per_view_rms_px", r.per_view_rms_px},
                      {"fx", r.camera.fx}, {"fy", r.camera.fy}, {"cx", r.camera.cx}, {"cy", r.camera.cy},
                      {"dist", r.camera.dist}};
  std::cout << j.dump(2) << "\n";
  return 0;
}

Eigen::Vector3d vec3(const YamlMap& m, const std::string& key) { return m.getVector3(key); }

int extrinsics(const Args& a) {
  const CameraIntrinsics cam = loadCameraInfoYaml(a.need("camera"));
  const std::string taught_file = a.need("taught");
  YamlMap t(loadYamlFile(taught_file), taught_file);
  const Eigen::Isometry3d T_base_pattern = frameFromThreePoints(vec3(t, "origin"), vec3(t, "on_x"), vec3(t, "in_xy"));
  t.finish();
  const cv::Mat grey = cv::imread(a.need("image"), cv::IMREAD_GRAYSCALE);
  if (grey.empty()) throw std::runtime_error(a.get("image") + ": cannot read the image");
  const ExtrinsicsResult r = calibrateExtrinsics(grey, board(a), cam, T_base_pattern);
  saveTransform(a.need("out"), a.get("parent", "base_link"), a.get("child", "scanner_camera_optical"),
                r.T_base_camera, r.rms_px, "pattern PnP + taught pattern frame (residual: reprojection RMS px)");
  const Eigen::Vector3d t_c = r.T_base_camera.translation();
  std::cout << nlohmann::json({{"output", a.get("out")}, {"rms_px", r.rms_px}, {"camera_position_m", {t_c.x(), t_c.y(), t_c.z()}}}).dump(2)
            << "\n";
  return 0;
}

int laser(const Args& a) {
  const CameraIntrinsics cam = loadCameraInfoYaml(a.need("camera"));
  const TransformCalibration cam_pose = loadTransformCalibration(a.need("camera-pose"));
  const std::vector<LaserObservation> obs = loadLaserObservations(a.need("observations"));
  const std::string method = a.get("method", "lsq");
  LineExtractionConfig line;
  LaserCalibrationResult r;
  if (method == "lsq") {
    r = calibrateLaserLeastSquares(obs, cam, cam_pose.T_parent_child, line);
  } else if (method == "three_point") {
    r = calibrateLaserThreePoint(obs.front(), cam, cam_pose.T_parent_child, line);
  } else {
    throw std::invalid_argument("--method must be lsq or three_point");
  }
  saveTransform(a.need("out"), a.get("flange", "flange"), a.get("child", "laser"), r.T_flange_laser, r.rms_m,
                method == "lsq" ? "least-squares sheet over " + std::to_string(obs.size()) + " observations (residual: m)"
                                : "three-point plate and gauge block (thesis)");
  std::cout << nlohmann::json({{"output", a.get("out")}, {"method", method}, {"points", r.points}, {"rms_mm", r.rms_m * 1e3},
                               {"spread_ratio", r.spread_ratio}})
                   .dump(2)
            << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::cerr << "usage: cellsight_calibrate intrinsics|extrinsics|laser [options] (see the source header)\n";
    return 2;
  }
  try {
    const std::string mode = argv[1];
    const Args a = parse(argc, argv);
    if (mode == "intrinsics") return intrinsics(a);
    if (mode == "extrinsics") return extrinsics(a);
    if (mode == "laser") return laser(a);
    std::cerr << "unknown mode '" << mode << "'\n";
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "error: " << e.what() << "\n";
    return 1;
  }
}
