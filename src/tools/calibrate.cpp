// Scanner calibration from files (each result written atomically; residuals reported as JSON).
// Usage: cellsight_calibrate SUBCOMMAND [OPTIONS]   (--help on the tool and on each subcommand)
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
// Bad or unknown options are reported by CLI11 (non-zero exit); failures at run time print
// "error: ..." and exit 1.
#include <algorithm>
#include <iostream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>

#include "cellsight/scanner/calibrate.hpp"
#include "cellsight/common/calibration.hpp"
#include "cellsight/common/file_io.hpp"
#include "cellsight/common/image_io.hpp"
#include "cellsight/common/yaml_reader.hpp"
#include "cli_args.hpp"

using namespace cellsight;

namespace {

struct Options {
  std::vector<std::string> images;
  std::string board, model = "full", name = "scanner_camera", out;
  double square = 0;
  bool fix_aspect = false;
  std::string camera, image, taught, parent = "base_link", child_camera = "scanner_camera_optical";
  std::string camera_pose, observations, method = "lsq", flange = "flange", child_laser = "laser";
};

/// "9x6": inner corners per row and column, both > 0.
cv::Size parseBoard(const std::string& s) {
  const auto x = s.find('x');
  auto positiveInt = [](const std::string& t) {
    if (t.empty() || t.size() > 4 || t.find_first_not_of("0123456789") != std::string::npos) return 0;
    return std::stoi(t);
  };
  const int w = x == std::string::npos ? 0 : positiveInt(s.substr(0, x));
  const int h = x == std::string::npos ? 0 : positiveInt(s.substr(x + 1));
  if (w <= 0 || h <= 0) throw std::invalid_argument("'" + s + "' must look like 9x6 (inner corners)");
  return cv::Size(w, h);
}

ChessboardSpec board(const Options& o) {
  ChessboardSpec b;
  b.inner_corners = parseBoard(o.board);
  b.square_size = o.square;
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

int intrinsics(const Options& o) {
  const auto files = listImages(o.images);
  if (files.empty()) throw std::invalid_argument("--images: no image files given or found");
  const DistortionModel model = parseDistortionModel(o.model);
  IntrinsicsResult r = calibrateIntrinsics(files, board(o), model, o.fix_aspect);
  r.camera.camera_name = o.name;
  const std::string& out = o.out;
  saveCameraInfoYaml(out, r.camera);
  nlohmann::json j = {{"output", out},
                      {"model", o.model},
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

int extrinsics(const Options& o) {
  const CameraIntrinsics cam = loadCameraInfoYaml(o.camera);
  const std::string& taught_file = o.taught;
  YamlMap t(loadYamlFile(taught_file), taught_file);
  const Eigen::Isometry3d T_base_pattern = frameFromThreePoints(vec3(t, "origin"), vec3(t, "on_x"), vec3(t, "in_xy"));
  t.finish();
  const cv::Mat grey = readImage(o.image, cv::IMREAD_GRAYSCALE);
  const ExtrinsicsResult r = calibrateExtrinsics(grey, board(o), cam, T_base_pattern);
  saveTransform(o.out, o.parent, o.child_camera,
                r.T_base_camera, r.rms_px, "pattern PnP + taught pattern frame (residual: reprojection RMS px)");
  const Eigen::Vector3d t_c = r.T_base_camera.translation();
  std::cout << nlohmann::json({{"output", o.out}, {"rms_px", r.rms_px}, {"camera_position_m", {t_c.x(), t_c.y(), t_c.z()}}}).dump(2)
            << "\n";
  return 0;
}

int laser(const Options& o) {
  const CameraIntrinsics cam = loadCameraInfoYaml(o.camera);
  const TransformCalibration cam_pose = loadTransformCalibration(o.camera_pose);
  const std::vector<LaserObservation> obs = loadLaserObservations(o.observations);
  const std::string& method = o.method;
  LineExtractionConfig line;
  LaserCalibrationResult r;
  if (method == "lsq") {
    r = calibrateLaserLeastSquares(obs, cam, cam_pose.T_parent_child, line);
  } else if (method == "three_point") {
    r = calibrateLaserThreePoint(obs.front(), cam, cam_pose.T_parent_child, line);
  } else {
    throw std::invalid_argument("--method must be lsq or three_point");
  }
  saveTransform(o.out, o.flange, o.child_laser, r.T_flange_laser, r.rms_m,
                method == "lsq" ? "least-squares sheet over " + std::to_string(obs.size()) + " observations (residual: m)"
                                : "three-point plate and gauge block (thesis)");
  std::cout << nlohmann::json({{"output", o.out}, {"method", method}, {"points", r.points}, {"rms_mm", r.rms_m * 1e3},
                               {"spread_ratio", r.spread_ratio}})
                   .dump(2)
            << "\n";
  return 0;
}

}  // namespace

int main(int argc, char** argv) {
  using cellsight_tools::positive;
  Options o;
  CLI::App app("Scanner calibration from files: camera intrinsics, camera pose (extrinsics), light sheet "
               "(laser). Each result is written atomically; residuals are printed as JSON.",
               "cellsight_calibrate");
  app.require_subcommand(1);
  const CLI::Validator board_check = cellsight_tools::parsedBy([](const std::string& s) { parseBoard(s); }, "WxH");

  CLI::App* in = app.add_subcommand("intrinsics", "camera intrinsics (Zhang) from chessboard images");
  in->add_option("--images", o.images, "image folders (*.png, *.jpg, *.jpeg, sorted) and/or image files")
      ->required()
      ->check(CLI::ExistingPath);
  in->add_option("--board", o.board, "inner corners per row x column, e.g. 9x6")->required()->check(board_check);
  in->add_option("--square", o.square, "chessboard square size [m]")->required()->check(positive());
  in->add_option("--model", o.model, "distortion model")->check(CLI::IsMember({"k1", "full"}))->capture_default_str();
  in->add_flag("--fix-aspect", o.fix_aspect, "fix fx/fy");
  in->add_option("--name", o.name, "camera_name written to the file")->capture_default_str();
  in->add_option("--out", o.out, "camera intrinsics YAML to write")->required();

  CLI::App* ex = app.add_subcommand(
      "extrinsics",
      "camera pose in the parent frame from one pattern image and the pattern frame taught by three points");
  ex->add_option("--camera", o.camera, "camera intrinsics YAML")->required()->check(CLI::ExistingFile);
  ex->add_option("--image", o.image, "pattern image")->required()->check(CLI::ExistingFile);
  ex->add_option("--board", o.board, "inner corners per row x column, e.g. 9x6")->required()->check(board_check);
  ex->add_option("--square", o.square, "chessboard square size [m]")->required()->check(positive());
  ex->add_option("--taught", o.taught,
                 "taught.yaml: {origin: [x,y,z], on_x: [x,y,z], in_xy: [x,y,z]} (metres, parent frame)")
      ->required()
      ->check(CLI::ExistingFile);
  ex->add_option("--parent", o.parent, "parent frame")->capture_default_str();
  ex->add_option("--child", o.child_camera, "child (camera) frame")->capture_default_str();
  ex->add_option("--out", o.out, "transform calibration YAML to write")->required();

  CLI::App* la = app.add_subcommand("laser", "light sheet -> flange from observations of a plate (and gauge block)");
  la->add_option("--camera", o.camera, "camera intrinsics YAML")->required()->check(CLI::ExistingFile);
  la->add_option("--camera-pose", o.camera_pose, "camera pose calibration YAML")->required()->check(CLI::ExistingFile);
  la->add_option("--observations", o.observations,
                 "obs.yaml: {observations: [{image: f.png, flange_pose: {xyz, rpy|quat}, plane_z: 0, block_z: 0.02}, ...]}")
      ->required()
      ->check(CLI::ExistingFile);
  la->add_option("--method", o.method, "least squares over all observations or the thesis's three-point method")
      ->check(CLI::IsMember({"lsq", "three_point"}))
      ->capture_default_str();
  la->add_option("--flange", o.flange, "parent (flange) frame")->capture_default_str();
  la->add_option("--child", o.child_laser, "child (laser) frame")->capture_default_str();
  la->add_option("--out", o.out, "transform calibration YAML to write")->required();

  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  return cellsight_tools::runTool([&] {
    makeDirs(parentDir(o.out));  // the output's folder, as a user expects of --out
    if (in->parsed()) return intrinsics(o);
    if (ex->parsed()) return extrinsics(o);
    return laser(o);
  });
}
