// Scanner calibration from files (each result written atomically; residuals reported as JSON).
// Usage: cellsight_calibrate SUBCOMMAND [OPTIONS]   (--help on the tool and on each subcommand)
//   intrinsics  --images <dir or files...> --board 9x6 --square 0.025 [--model k1|full]
//               [--pattern chessboard|circles|acircles|charuco [--marker 0.018 --dictionary 4x4_50]]
//               [--refine adaptive|fixed|sb] [--view-rms-limit 1.0 [--drop-high-rms]]
//               [--fix-aspect] [--name scanner_camera] [--corners corners.json] [--plot views.png]
//               --out camera.yaml   (ROS camera_calibration YAML, as camera drivers load it)
//   extrinsics  --camera camera.yaml --image pattern.png --board 9x6 --square 0.025
//               --taught taught.yaml [--parent base_link] [--child scanner_camera_optical] --out pose.yaml
//               taught.yaml: {origin: [x,y,z], on_x: [x,y,z], in_xy: [x,y,z]} (metres, parent frame):
//               the pattern's first inner corner, a point on its row direction, a point on its plane
//   laser       --camera camera.yaml --camera-pose pose.yaml --observations obs.yaml
//               [--method lsq|three_point] [--flange flange] [--child laser] --out laser.yaml
//               obs.yaml: {observations: [{image: f.png, flange_pose: {xyz, rpy|quat}, plane_z: 0,
//               block_z: 0.02}, ...]} (image paths relative to obs.yaml)
//   hand_eye    --camera camera.yaml --poses flange_poses.yaml --board 9x6 --square 0.03
//               [--touched touched.yaml] [--method refined|axes|tsai|park|horaud|andreff|daniilidis|visp]
//               [--parent base_link] [--child scanner_camera_optical] --out pose.yaml
//               a stationary camera's pose from views of a board the robot carries; every method
//               is run and reported, the chosen one written
// Bad or unknown options are reported by CLI11 (non-zero exit); failures at run time print
// "error: ..." and exit 1.
#include <algorithm>
#include <iostream>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <opencv2/calib3d.hpp>

#include "cellsight/scanner/calibrate.hpp"
#include "cellsight/common/calibration.hpp"
#include "cellsight/common/file_io.hpp"
#include "cellsight/common/image_io.hpp"
#include "cellsight/common/yaml_reader.hpp"
#include "cellsight/fixtures/hand_eye.hpp"
#include "cli_args.hpp"

using namespace cellsight;

namespace {

struct Options {
  std::vector<std::string> images;
  std::string board, model = "full", name = "scanner_camera", out;
  std::string pattern = "chessboard", refine = "adaptive", dictionary = "4x4_50", corners, plot;
  double square = 0, marker = 0, view_rms_limit = 1.0;
  bool fix_aspect = false, drop_high_rms = false;
  std::string camera, image, taught, parent = "base_link", child_camera = "scanner_camera_optical";
  std::string camera_pose, observations, method = "lsq", flange = "flange", child_laser = "laser";
  std::string poses, touched, hand_eye_method = "refined";
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
  b.kind = ChessboardSpec::parseKind(o.pattern);
  b.refinement = ChessboardSpec::parseRefinement(o.refine);
  b.marker_size = o.marker;
  b.dictionary = o.dictionary;
  if (b.kind == ChessboardSpec::Kind::kCharuco && !(o.marker > 0 && o.marker < o.square)) {
    throw std::invalid_argument("--pattern charuco needs --marker (the marker side in metres, smaller than --square)");
  }
  return b;
}

/// Per-view reprojection RMS as a bar chart (PNG): the threshold as a line, flagged views red.
cv::Mat viewPlot(const IntrinsicsResult& r, double limit) {
  const int n = static_cast<int>(r.per_view_rms_px.size()), bar = std::max(6, std::min(40, 900 / std::max(1, n)));
  const int W = 80 + n * bar + 20, H = 360, top = 30, bottom = H - 50;
  double ymax = limit * 1.2;
  for (double v : r.per_view_rms_px) ymax = std::max(ymax, v * 1.1);
  cv::Mat img(H, W, CV_8UC3, cv::Scalar(255, 255, 255));
  auto y = [&](double v) { return static_cast<int>(bottom - (bottom - top) * v / ymax); };
  cv::line(img, {70, top}, {70, bottom}, cv::Scalar(0, 0, 0));
  cv::line(img, {70, bottom}, {W - 10, bottom}, cv::Scalar(0, 0, 0));
  for (int k = 0; k <= 4; ++k) {
    const double v = ymax * k / 4;
    char t[32];
    std::snprintf(t, sizeof t, "%.2f", v);
    cv::putText(img, t, {10, y(v) + 4}, cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(0, 0, 0));
  }
  for (int i = 0; i < n; ++i) {
    const double v = r.per_view_rms_px[static_cast<size_t>(i)];
    const cv::Scalar c = v > limit ? cv::Scalar(40, 40, 220) : cv::Scalar(180, 120, 40);
    cv::rectangle(img, {72 + i * bar, y(v)}, {72 + (i + 1) * bar - 2, bottom - 1}, c, cv::FILLED);
    if (n <= 40 || i % 5 == 0) {
      cv::putText(img, std::to_string(i), {72 + i * bar, bottom + 15}, cv::FONT_HERSHEY_SIMPLEX, 0.35, cv::Scalar(0, 0, 0));
    }
  }
  cv::line(img, {70, y(limit)}, {W - 10, y(limit)}, cv::Scalar(40, 40, 220), 1, cv::LINE_AA);
  char title[128];
  std::snprintf(title, sizeof title, "reprojection RMS per view [px]; overall %.3f px; red: above %.2f px", r.rms_px, limit);
  cv::putText(img, title, {10, 18}, cv::FONT_HERSHEY_SIMPLEX, 0.45, cv::Scalar(0, 0, 0));
  cv::putText(img, "view (order of views_used)", {W / 2 - 80, H - 15}, cv::FONT_HERSHEY_SIMPLEX, 0.4, cv::Scalar(0, 0, 0));
  return img;
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
  IntrinsicsOptions opt;
  opt.model = parseDistortionModel(o.model);
  opt.fix_aspect_ratio = o.fix_aspect;
  opt.view_rms_threshold_px = o.view_rms_limit;
  opt.drop_high_rms_views = o.drop_high_rms;
  IntrinsicsResult r = calibrateIntrinsics(files, board(o), opt);
  r.camera.camera_name = o.name;
  const std::string& out = o.out;
  saveCameraInfoYaml(out, r.camera);
  nlohmann::json j = {{"output", out},
                      {"model", o.model},
                      {"pattern", o.pattern},
                      {"rms_px", r.rms_px},
                      {"views_used", r.used},
                      {"views_rejected", r.rejected},
                      {"per_view_rms_px", r.per_view_rms_px},
                      {"high_rms_views", r.high_rms_views},
                      {"dropped", r.dropped},
                      {"warnings", r.warnings},
                      {"fx", r.camera.fx}, {"fy", r.camera.fy}, {"cx", r.camera.cx}, {"cy", r.camera.cy},
                      {"dist", r.camera.dist}};
  if (!o.corners.empty()) {
    nlohmann::json views = nlohmann::json::array();
    for (size_t i = 0; i < r.used.size(); ++i) {
      nlohmann::json pts = nlohmann::json::array();
      const PatternView& v = r.detections[i];
      for (size_t k = 0; k < v.image.size(); ++k) {
        pts.push_back({{"id", v.ids[k]}, {"u", v.image[k].x}, {"v", v.image[k].y},
                       {"board_m", {v.object[k].x, v.object[k].y}}});
      }
      views.push_back({{"file", r.used[i]}, {"rms_px", r.per_view_rms_px[i]}, {"points", pts}});
    }
    writeFileAtomic(o.corners, nlohmann::json({{"pattern", o.pattern}, {"board", o.board}, {"views", views}}).dump(1) + "\n");
  }
  if (!o.plot.empty()) {
    std::vector<uchar> png;
    cv::imencode(".png", viewPlot(r, opt.view_rms_threshold_px), png);
    writeFileAtomic(o.plot, std::string(png.begin(), png.end()));
  }
  for (const auto& w : r.warnings) std::cerr << "warning: " << w << "\n";
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

// A stationary camera to the robot (eye-to-hand) from views of a board carried by the robot.
int handEye(const Options& o) {
  const CameraIntrinsics cam = loadCameraInfoYaml(o.camera);
  YamlMap m(loadYamlFile(o.poses), o.poses);
  HandEyeInput in;
  in.camera = cam;
  const int axes_reference = m.getInt("axes_reference", -1);
  std::vector<int> axes_moves;
  if (m.has("axes_moves")) {
    for (const auto& n : m.raw("axes_moves")) axes_moves.push_back(n.as<int>());
  }
  const ChessboardSpec b = board(o);
  const cv::Matx33d K(cam.fx, 0, cam.cx, 0, cam.fy, cam.cy, 0, 0, 1);
  const std::vector<double> dist(cam.dist.begin(), cam.dist.end());
  std::vector<std::string> missed;
  std::vector<int> index_of;  // file view → input view, -1 when the board was not found
  size_t expected_points = 0;
  for (const YamlMap& v : m.getMapList("views")) {
    const std::string image = resolveRelative(o.poses, v.getString("image"));
    const Eigen::Isometry3d F = v.getPose("flange");
    v.finish();
    PatternView pv;
    const cv::Mat grey = readImage(image, cv::IMREAD_GRAYSCALE);
    if (grey.cols != cam.width || grey.rows != cam.height) {
      throw std::runtime_error(image + " is " + std::to_string(grey.cols) + "x" + std::to_string(grey.rows) +
                               " but " + o.camera + " calibrates " + std::to_string(cam.width) + "x" + std::to_string(cam.height));
    }
    if (!detectPattern(grey, b, pv) || (expected_points && pv.image.size() != expected_points)) {
      missed.push_back(image);
      index_of.push_back(-1);
      continue;
    }
    expected_points = pv.image.size();
    if (in.target_points.empty()) {
      for (const auto& p : pv.object) in.target_points.emplace_back(p.x, p.y, p.z);
    }
    cv::Vec3d rvec, tvec;
    cv::solvePnP(pv.object, pv.image, K, dist, rvec, tvec, false, cv::SOLVEPNP_ITERATIVE);
    cv::Matx33d R;
    cv::Rodrigues(rvec, R);
    HandEyeView hv;
    hv.T_base_flange = F;
    for (int i = 0; i < 3; ++i) {
      for (int j = 0; j < 3; ++j) hv.T_camera_target.linear()(i, j) = R(i, j);
      hv.T_camera_target.translation()(i) = tvec[i];
    }
    for (const auto& p : pv.image) hv.corners.emplace_back(p.x, p.y);
    index_of.push_back(static_cast<int>(in.views.size()));
    in.views.push_back(std::move(hv));
  }
  m.finish();
  auto mapped = [&](int k) { return k >= 0 && k < static_cast<int>(index_of.size()) ? index_of[static_cast<size_t>(k)] : -1; };
  in.axes_reference = mapped(axes_reference);
  for (int k : axes_moves) {
    if (mapped(k) >= 0) in.axes_moves.push_back(mapped(k));
  }
  if (!o.touched.empty()) {
    YamlMap t(loadYamlFile(o.touched), o.touched);
    in.touched_origin = t.getVector3("origin");
    t.finish();
  }
  const HandEyeMethod chosen = parseHandEyeMethod(o.hand_eye_method);
  nlohmann::json methods = nlohmann::json::object();
  HandEyeResult result;
  for (HandEyeMethod method : allHandEyeMethods()) {
    if (method == HandEyeMethod::kAxes && (in.axes_reference < 0 || o.touched.empty())) continue;
    const HandEyeResult r = calibrateEyeToHand(in, method);
    nlohmann::json j = {{"ok", r.ok}};
    if (r.ok) {
      const Eigen::Vector3d t = r.T_base_camera.translation();
      const Eigen::Quaterniond q(r.T_base_camera.linear());
      j.update({{"camera_xyz", {t.x(), t.y(), t.z()}}, {"camera_quat", {q.x(), q.y(), q.z(), q.w()}},
                {"residual_mm", r.residual_translation * 1000}, {"residual_deg", r.residual_rotation * 180 / M_PI}});
      if (method == HandEyeMethod::kRefined) j["reprojection_rms_px"] = r.reprojection_rms_px;
    } else {
      j["error"] = r.error;
    }
    methods[handEyeMethodName(method)] = j;
    if (method == chosen) result = r;
  }
  if (!result.ok) {
    throw std::runtime_error("hand-eye calibration (" + o.hand_eye_method + ") failed: " +
                             (result.error.empty() ? "method not run (the axes method needs --touched and axes views)" : result.error));
  }
  saveTransform(o.out, o.parent, o.child_camera, result.T_base_camera,
                chosen == HandEyeMethod::kRefined ? result.reprojection_rms_px : result.residual_translation,
                "eye-to-hand calibration, " + o.hand_eye_method + ", " + std::to_string(in.views.size()) + " views (residual: " +
                    (chosen == HandEyeMethod::kRefined ? "reprojection RMS px" : "m") + ")");
  for (const auto& mm : missed) std::cerr << "warning: no complete board in " << mm << " (view left out)\n";
  std::cout << nlohmann::json({{"output", o.out}, {"method", o.hand_eye_method}, {"views", in.views.size()},
                               {"missed", missed}, {"methods", methods}})
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
  in->add_option("--board", o.board,
                 "chessboard: inner corners per row x column (e.g. 9x6); circles: centres per row x column; charuco: "
                 "squares per row x column")
      ->required()
      ->check(board_check);
  in->add_option("--square", o.square, "square size (circles: centre spacing) [m]")->required()->check(positive());
  in->add_option("--pattern", o.pattern, "calibration target")
      ->check(CLI::IsMember({"chessboard", "circles", "acircles", "charuco"}))
      ->capture_default_str();
  in->add_option("--marker", o.marker, "charuco: marker side [m]")->check(positive());
  in->add_option("--dictionary", o.dictionary, "charuco: ArUco dictionary (4x4_50, 5x5_100, 6x6_250, original, ...)")
      ->check(cellsight_tools::parsedBy([](const std::string& d) { checkArucoDictionary(d); }, "DICTIONARY"))
      ->capture_default_str();
  in->add_option("--refine", o.refine,
                 "chessboard corners: adaptive (cornerSubPix window from the square size in px), fixed (winSize 11x11, "
                 "a 23x23 window), sb "
                 "(findChessboardCornersSB)")
      ->check(CLI::IsMember({"adaptive", "fixed", "sb"}))
      ->capture_default_str();
  in->add_option("--model", o.model, "distortion model")->check(CLI::IsMember({"k1", "full"}))->capture_default_str();
  in->add_option("--view-rms-limit", o.view_rms_limit,
                 "views reprojecting worse than max(this, 3 x the median view) are reported [px]")
      ->check(positive())
      ->capture_default_str();
  in->add_flag("--drop-high-rms", o.drop_high_rms, "drop the reported views and calibrate again");
  in->add_flag("--fix-aspect", o.fix_aspect, "fix fx/fy");
  in->add_option("--name", o.name, "camera_name written to the file")->capture_default_str();
  in->add_option("--corners", o.corners, "write the detected corners per view (JSON)");
  in->add_option("--plot", o.plot, "write the per-view reprojection RMS plot (PNG)");
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

  CLI::App* he = app.add_subcommand(
      "hand_eye", "a stationary camera's pose in the robot base from views of a board the robot carries (eye-to-hand)");
  he->add_option("--camera", o.camera, "camera intrinsics YAML")->required()->check(CLI::ExistingFile);
  he->add_option("--poses", o.poses,
                 "flange_poses.yaml: {views: [{image: view_00.png, flange: {xyz, rpy|quat}}, ...], axes_reference: 0, "
                 "axes_moves: [1, ...]} (images relative to it)")
      ->required()
      ->check(CLI::ExistingFile);
  he->add_option("--board", o.board, "inner corners per row x column, e.g. 9x6")->required()->check(board_check);
  he->add_option("--square", o.square, "chessboard square size [m]")->required()->check(positive());
  he->add_option("--touched", o.touched, "touched.yaml {origin: [x,y,z]}: the board origin touched in the reference view (axes method)")
      ->check(CLI::ExistingFile);
  he->add_option("--method", o.hand_eye_method, "the result written: axes | tsai | park | horaud | andreff | daniilidis | visp | refined")
      ->check(CLI::IsMember({"axes", "tsai", "park", "horaud", "andreff", "daniilidis", "visp", "refined"}))
      ->capture_default_str();
  he->add_option("--parent", o.parent, "parent frame")->capture_default_str();
  he->add_option("--child", o.child_camera, "child (camera) frame")->capture_default_str();
  he->add_option("--out", o.out, "transform calibration YAML to write")->required();

  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  return cellsight_tools::runTool([&] {
    makeDirs(parentDir(o.out));  // the output's folder, as a user expects of --out
    if (in->parsed()) return intrinsics(o);
    if (ex->parsed()) return extrinsics(o);
    if (he->parsed()) return handEye(o);
    return laser(o);
  });
}
