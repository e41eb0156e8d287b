// Calibration: real chessboard data (../shared/data) and simulated laser-sheet calibration.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <opencv2/calib3d.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include <fstream>
#include <functional>
#include <nlohmann/json.hpp>

#include "cellsight/common/yaml_reader.hpp"
#include "cellsight/eval/sim_scan.hpp"
#include "cellsight/eval/evaluation.hpp"
#include "cellsight/scanner/accuracy.hpp"
#include "cellsight/scanner/calibrate.hpp"
#include "cellsight/scanner/triangulation.hpp"
#include "cellsight/sim/calibration_captures.hpp"
#include "sim/sim_test_scenes.hpp"

using namespace cellsight;

namespace {
const std::string kData = std::string(CELLSIGHT_SOURCE_DIR) + "/../shared/data";
bool exists(const std::string& p) {
  struct stat st {};
  return ::stat(p.c_str(), &st) == 0;
}
#define REQUIRE_DATA(path)                                                         \
  if (!exists(path)) GTEST_SKIP() << "real data not found at " << (path) << " (../shared/data)"
}  // namespace

TEST(RealData, OpenCvChessboardFullModelMatchesOpenCvsOwnResult) {
  const std::string dir = kData + "/calibration/opencv_chessboard_9x6";
  REQUIRE_DATA(dir);
  std::vector<std::string> files;
  for (int i : {1, 2, 3, 4, 5, 6, 7, 8, 9, 11, 12, 13, 14}) {
    char name[32];
    std::snprintf(name, sizeof(name), "/left%02d.jpg", i);
    files.push_back(dir + name);
  }
  const IntrinsicsResult full = calibrateIntrinsics(files, {{9, 6}, 0.025}, DistortionModel::kFull);
  const IntrinsicsResult k1 = calibrateIntrinsics(files, {{9, 6}, 0.025}, DistortionModel::kK1);
  ChessboardSpec fixed{{9, 6}, 0.025};
  fixed.refinement = ChessboardSpec::Refinement::kFixed;  // OpenCV's sample window, as OpenCV's own result
  const IntrinsicsResult ocv = calibrateIntrinsics(files, fixed, DistortionModel::kFull);
  std::printf("opencv_chessboard_9x6: full model RMS %.4f px (fixed 23x23 window %.4f px; OpenCV 0.393), k1 only "
              "%.4f px, fx %.2f\n",
              full.rms_px, ocv.rms_px, k1.rms_px, full.camera.fx);
  EXPECT_EQ(full.used.size(), 13u);
  EXPECT_NEAR(ocv.rms_px, 0.393, 0.0393);  // the library path reproduces OpenCV's own figure
  EXPECT_LT(full.rms_px, ocv.rms_px);      // the window from the square size: better
  EXPECT_NEAR(full.camera.fx, 535.92, 5.0);
  EXPECT_TRUE(full.warnings.empty()) << full.warnings.front();
  EXPECT_GE(k1.rms_px, full.rms_px);
}

TEST(RealData, FabScanPiChessboardAndLaserFrames) {
  const std::string dir = kData + "/laser/fabscanpi";
  REQUIRE_DATA(dir);
  std::vector<std::string> files;
  for (int i = 0; i <= 40; i += 8) {
    char name[64];
    std::snprintf(name, sizeof(name), "/calibration_8x10/calibration_%03d.jpg", i);
    files.push_back(dir + name);
  }
  const IntrinsicsResult r = calibrateIntrinsics(files, {{8, 10}, 0.007}, DistortionModel::kFull);
  std::printf("fabscanpi: %zu views, RMS %.3f px, fx %.1f cx %.1f cy %.1f\n", r.used.size(), r.rms_px, r.camera.fx,
              r.camera.cx, r.camera.cy);
  EXPECT_GE(r.used.size(), 4u);
  EXPECT_LT(r.rms_px, 1.0);
  EXPECT_NEAR(r.camera.cx, 1640 / 2.0, 60);  // landscape frames: principal point near the centre
  // Line extraction on the real frames, against the threshold rule of lineCoverage() (checked by
  // eye on overlays: `cellsight_extract_line --reference-contrast 40 --overlay-dir ...`).
  LineExtractionConfig ridge, cols;
  ridge.channel = cols.channel = 0;  // red laser
  cols.estimator = LineExtractionConfig::Estimator::kCentroid;
  LineCoverageRule rule;  // contrast 40, runs up to 16 px
  long crossings = 0, ridge_covered = 0, cols_covered = 0, ridge_centres = 0, ridge_false = 0;
  for (int i = 10; i <= 90; i += 20) {
    char name[96];
    std::snprintf(name, sizeof(name), "/scan_res1_laser1/20210213-230202_%03d.jpg", i);
    cv::Mat img = cv::imread(dir + name, cv::IMREAD_COLOR);
    ASSERT_FALSE(img.empty()) << name;
    cv::cvtColor(img, img, cv::COLOR_BGR2RGB);
    cv::Mat red;
    cv::extractChannel(img, red, 0);
    const LineCoverage r = lineCoverage(red, extractLine(img, ridge), rule);
    const LineCoverage c = lineCoverage(red, extractLine(img, cols), rule);
    crossings += r.crossings;
    ridge_covered += r.covered;
    ridge_centres += r.centres;
    ridge_false += r.false_centres;
    cols_covered += c.covered;
  }
  const double ridge_share = double(ridge_covered) / crossings, cols_share = double(cols_covered) / crossings;
  std::printf("fabscanpi line: %ld crossings; ridge %.3f covered, %.4f false; column centroid %.3f covered\n", crossings,
              ridge_share, double(ridge_false) / ridge_centres, cols_share);
  EXPECT_GT(ridge_share, 0.92);  // all 101 frames: 95.6 % (docs/scanner.md)
  EXPECT_LT(double(ridge_false) / ridge_centres, 0.02);
  EXPECT_GT(ridge_share, cols_share + 0.3);  // the steep parts
}

TEST(Calibration, FrameFromThreeTaughtPoints) {
  const Eigen::Isometry3d T = frameFromThreePoints({0.5, 0.1, 0.02}, {0.6, 0.1, 0.02}, {0.45, 0.3, 0.02});
  EXPECT_TRUE(T.linear().isApprox(Eigen::Matrix3d::Identity(), 1e-12));
  EXPECT_THROW(frameFromThreePoints({0, 0, 0}, {1, 0, 0}, {2, 0, 0}), std::invalid_argument);
}

TEST(Calibration, ExtrinsicsFromASyntheticPatternImage) {
  // A 9x6 board (25 mm) drawn into a 1280x960 camera at a known pose by a homography.
  const ChessboardSpec board{{9, 6}, 0.025};
  CameraIntrinsics cam{"c", 1280, 960, 1100, 1100, 639.5, 479.5, {0, 0, 0, 0, 0}};
  Eigen::Isometry3d T_camera_pattern = Eigen::Translation3d(-0.1, -0.06, 0.6) *
                                       Eigen::AngleAxisd(0.2, Eigen::Vector3d(1, 0.5, 0).normalized());
  const int px_per_sq = 40, margin = 60;
  cv::Mat flat(px_per_sq * 7 + 2 * margin, px_per_sq * 10 + 2 * margin, CV_8UC1, cv::Scalar(255));
  for (int r = 0; r < 7; ++r)
    for (int c = 0; c < 10; ++c)
      if ((r + c) % 2 == 0)
        cv::rectangle(flat, cv::Rect(margin + c * px_per_sq, margin + r * px_per_sq, px_per_sq, px_per_sq), 0, cv::FILLED);
  // Flat-image pixel → pattern metres: the first inner corner is at (margin + px, margin + px).
  std::vector<cv::Point2f> src, dst;
  for (auto [x, y] : std::vector<std::pair<double, double>>{{0, 0}, {0.2, 0}, {0.2, 0.15}, {0, 0.15}}) {
    src.emplace_back(static_cast<float>(margin + px_per_sq + x / 0.025 * px_per_sq),
                     static_cast<float>(margin + px_per_sq + y / 0.025 * px_per_sq));
    const Eigen::Vector2d uv = cam.project(T_camera_pattern * Eigen::Vector3d(x, y, 0));
    dst.emplace_back(static_cast<float>(uv.x()), static_cast<float>(uv.y()));
  }
  cv::Mat img;
  cv::warpPerspective(flat, img, cv::getPerspectiveTransform(src, dst), cv::Size(1280, 960), cv::INTER_LINEAR,
                      cv::BORDER_CONSTANT, cv::Scalar(128));
  const Eigen::Isometry3d T_base_pattern = Eigen::Translation3d(0.4, 0.0, 0.0) * Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ());
  const ExtrinsicsResult r = calibrateExtrinsics(img, board, cam, T_base_pattern);
  const Eigen::Isometry3d truth = T_base_pattern * T_camera_pattern.inverse();
  EXPECT_LT(r.rms_px, 0.3);
  EXPECT_LT((r.T_base_camera.translation() - truth.translation()).norm(), 1e-3);
  EXPECT_LT(Eigen::AngleAxisd(r.T_base_camera.linear().transpose() * truth.linear()).angle(), 2e-3);
}

namespace {
double angleBetweenPlanes(const Plane& a, const Plane& b) {
  return std::acos(std::min(1.0, std::abs(a.n.dot(b.n))));
}
double offsetAtPoint(const Plane& a, const Plane& b, const Eigen::Vector3d& p) {
  // distance along the normal between the planes near p
  return std::abs(a.distance(p) - (a.n.dot(b.n) > 0 ? 1 : -1) * b.distance(p));
}
}  // namespace

TEST(Calibration, LaserSheetLeastSquaresRecoversTheSimulatedSheet) {
  Scene s = cellsight_test::planeScene();
  s.scanner_camera.intrinsics = {"c", 1280, 960, 1500, 1500, 639.5, 479.5, {-0.05, 0.02, 0, 0, 0}};
  s.scanner_camera.T_base_camera = cellsight_test::lookDown({0, 0, 0.6});
  s.noise.enabled = true;
  s.laser.line_width = 0.8e-3;
  s.laser.T_flange_laser = Eigen::Translation3d(0, 0.06, 0.04) * Eigen::AngleAxisd(0.5236, Eigen::Vector3d::UnitX());
  ScannerRenderer r(std::make_shared<CellGeometry>(s));
  std::vector<LaserObservation> obs;
  for (int i = 0; i < 8; ++i) {  // several heights and tilts over a flat plate (the table)
    Eigen::Isometry3d F = cellsight_test::lookDown({0.01 * i, -0.12 + 0.01 * i, 0.22 + 0.02 * i});
    F.rotate(Eigen::AngleAxisd(0.05 * (i % 3) - 0.05, Eigen::Vector3d::UnitX()));
    obs.push_back({r.render(F, 10 + i), F, 0.0, 0.0});
  }
  const LaserCalibrationResult res = calibrateLaserLeastSquares(obs, s.scanner_camera.intrinsics,
                                                                s.scanner_camera.T_base_camera, {});
  const Plane truth = laserPlane(s.laser.T_flange_laser);
  std::printf("sheet LSQ: %zu points, RMS %.4f mm, angle error %.4f deg, offset %.4f mm, spread %.3f\n", res.points,
              res.rms_m * 1e3, angleBetweenPlanes(res.plane_flange, truth) * 180 / M_PI,
              offsetAtPoint(res.plane_flange, truth, Eigen::Vector3d(0, 0.1, 0.25)) * 1e3, res.spread_ratio);
  EXPECT_LT(angleBetweenPlanes(res.plane_flange, truth), 0.02 * M_PI / 180);
  EXPECT_LT(offsetAtPoint(res.plane_flange, truth, Eigen::Vector3d(0, 0.1, 0.25)), 0.02e-3);
  EXPECT_NEAR(laserPlane(res.T_flange_laser).distance(Eigen::Vector3d(0, 0.1, 0.25)),
              res.plane_flange.distance(Eigen::Vector3d(0, 0.1, 0.25)), 1e-12);
  // One pose over one plate: all points on one line → refused, not a silent wrong answer.
  EXPECT_THROW(calibrateLaserLeastSquares({obs[0]}, s.scanner_camera.intrinsics, s.scanner_camera.T_base_camera, {}),
               std::runtime_error);
  // Degenerate robot poses: all parallel at one height, moved along the surface only.
  std::vector<LaserObservation> parallel;
  for (int i = 0; i < 4; ++i) {
    const Eigen::Isometry3d F = cellsight_test::lookDown({0.015 * i, -0.12 + 0.01 * i, 0.25});
    parallel.push_back({r.render(F, 30 + i), F, 0.0, 0.0});
  }
  try {
    calibrateLaserLeastSquares(parallel, s.scanner_camera.intrinsics, s.scanner_camera.T_base_camera, {});
    ADD_FAILURE() << "parallel poses at one height were accepted";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("flange heights or tilts"), std::string::npos) << e.what();
  }
}

TEST(Calibration, LaserSheetThreePointPlateAndGaugeBlock) {
  const std::string dir = cellsight_test::tempDir();
  Scene s = cellsight_test::planeScene();
  s.scanner_camera.intrinsics = {"c", 1280, 960, 1500, 1500, 639.5, 479.5, {0, 0, 0, 0, 0}};
  s.scanner_camera.T_base_camera = cellsight_test::lookDown({0, 0, 0.6});
  s.noise.enabled = false;
  s.laser.line_width = 0.8e-3;
  s.laser.T_flange_laser = Eigen::Translation3d(0, 0.06, 0.04) * Eigen::AngleAxisd(0.5236, Eigen::Vector3d::UnitX());
  cellsight_test::addObject(s, dir, "gauge", makeBox({0.05, 0.04, 0.02}), Eigen::Isometry3d(Eigen::Translation3d(0.04, 0.0, 0.01)));
  ScannerRenderer r(std::make_shared<CellGeometry>(s));
  // Flange such that the sheet crosses the plate and the 20 mm block (line near y = 0).
  const Eigen::Isometry3d F = cellsight_test::lookDown({0.0, -0.07, 0.26});
  LaserObservation o{r.render(F, 3), F, 0.0, 0.02};
  const LaserCalibrationResult res = calibrateLaserThreePoint(o, s.scanner_camera.intrinsics, s.scanner_camera.T_base_camera, {});
  const Plane truth = laserPlane(s.laser.T_flange_laser);
  std::printf("sheet three-point: angle error %.4f deg\n", angleBetweenPlanes(res.plane_flange, truth) * 180 / M_PI);
  EXPECT_LT(angleBetweenPlanes(res.plane_flange, truth), 0.2 * M_PI / 180);
}

// The whole calibration a user makes, on simulated captures of the demo cell as built (its
// camera and laser off their drawing, its robot with kinematic error): each result against the
// truth the pipeline never sees.
TEST(SelfCalibration, SimulatedCapturesOfTheCellAsBuilt) {
  const std::string dir = cellsight_test::tempDir();
  const Scene scene = loadScene(std::string(CELLSIGHT_SOURCE_DIR) + "/config/scenes/demo.yaml");
  ASSERT_FALSE(scene.as_built.perfect);
  CalibrationCaptureConfig cc;
  cc.intrinsic_views = 10;
  cc.laser_views = 8;
  const CalibrationCaptureFiles f = writeCalibrationCaptures(scene, dir, cc);
  const ChessboardSpec board{{cc.board_cols, cc.board_rows}, cc.square};
  const IntrinsicsResult in = calibrateIntrinsics(listImages({f.intrinsics_dir}), board, DistortionModel::kFull);
  ASSERT_EQ(in.used.size(), 10u);
  const CameraIntrinsics& K = scene.scanner_camera.intrinsics;
  EXPECT_LT(in.rms_px, 0.3);
  EXPECT_NEAR(in.camera.fx, K.fx, 0.005 * K.fx);
  EXPECT_NEAR(in.camera.cx, K.cx, 3.0);

  YamlMap t(loadYamlFile(f.taught), f.taught);
  const Eigen::Isometry3d T_base_pattern = frameFromThreePoints(t.getVector3("origin"), t.getVector3("on_x"), t.getVector3("in_xy"));
  const ExtrinsicsResult ex = calibrateExtrinsics(cv::imread(f.pattern_image, cv::IMREAD_GRAYSCALE), board, in.camera, T_base_pattern);
  const Eigen::Isometry3d& Tc = scene.scanner_camera.T_base_camera;
  const double cam_pos = (ex.T_base_camera.translation() - Tc.translation()).norm();
  const double cam_rot = Eigen::AngleAxisd(ex.T_base_camera.linear().transpose() * Tc.linear()).angle();
  EXPECT_LT(cam_pos, 2e-3);  // taught with a robot that errs by a few tenths of a mm
  EXPECT_LT(cam_rot, 0.2 * M_PI / 180);

  const auto obs = loadLaserObservations(f.laser_obs);
  const LaserCalibrationResult lsq = calibrateLaserLeastSquares(obs, in.camera, ex.T_base_camera, {});
  const Plane truth = laserPlane(scene.laser.T_flange_laser);
  const Eigen::Vector3d probe = scene.laser.T_flange_laser * Eigen::Vector3d(0, 0, 0.25);
  const auto three = loadLaserObservations(f.three_point_obs);
  const LaserCalibrationResult tp = calibrateLaserThreePoint(three.front(), in.camera, ex.T_base_camera, {});
  std::printf("self-calibration: fx %.2f (true %.2f), camera %.3f mm %.4f deg, sheet LSQ %.4f deg %.4f mm, "
              "three-point %.4f deg %.4f mm\n",
              in.camera.fx, K.fx, cam_pos * 1e3, cam_rot * 180 / M_PI, angleBetweenPlanes(lsq.plane_flange, truth) * 180 / M_PI,
              std::abs(lsq.plane_flange.distance(probe)) * 1e3, angleBetweenPlanes(tp.plane_flange, truth) * 180 / M_PI,
              std::abs(tp.plane_flange.distance(probe)) * 1e3);
  EXPECT_LT(angleBetweenPlanes(lsq.plane_flange, truth), 0.1 * M_PI / 180);
  EXPECT_LT(std::abs(lsq.plane_flange.distance(probe)), 0.3e-3);
  EXPECT_LT(angleBetweenPlanes(tp.plane_flange, truth), 0.5 * M_PI / 180);
}

TEST(SelfCalibration, BadCapturesAreRefusedWithTheirCause) {
  const Scene scene = loadScene(std::string(CELLSIGHT_SOURCE_DIR) + "/config/scenes/demo.yaml");
  CalibrationCaptureConfig cc;
  const ChessboardSpec board{{cc.board_cols, cc.board_rows}, cc.square};
  const CameraIntrinsics& K = scene.scanner_camera.intrinsics;
  const auto message = cellsight_test::errorOf;
  // no pattern in the image (the bare table)
  cv::Mat table(K.height, K.width, CV_8UC1, cv::Scalar(100));
  EXPECT_NE(message([&] { calibrateExtrinsics(table, board, K, Eigen::Isometry3d::Identity()); }).find("not found"),
            std::string::npos);
  // the board half out of view: its centre on the image's right edge
  const CameraConfig& cam = scene.scanner_camera;
  const Eigen::Vector3d d = cam.T_base_camera.linear() * K.pixelRay(Eigen::Vector2d(K.width - 1, K.height / 2.0));
  const Eigen::Vector3d edge = cam.T_base_camera.translation() - cam.T_base_camera.translation().z() / d.z() * d;
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  T.translation() = edge - T.linear() * Eigen::Vector3d(0.1, 0.0625, 0);
  const cv::Mat half = renderChessboardView(scene, cam, T, cc, 1);
  EXPECT_NE(message([&] { calibrateExtrinsics(half, board, K, T); }).find("whole board in view"), std::string::npos);
  // a board that looks the same after a half turn gives no unique frame
  EXPECT_NE(message([&] { calibrateExtrinsics(half, ChessboardSpec{{8, 6}, 0.025}, K, T); }).find("half turn"),
            std::string::npos);
  // too few views for the intrinsics
  EXPECT_NE(message([&] { calibrateIntrinsics({{"a", half}, {"b", table}}, board, DistortionModel::kFull); }).find("at least 3 views"),
            std::string::npos);
}

TEST(RealData, FabScanPiFramesTriangulateOntoTheTurntable) {
  // The real scan end to end with the scanner's own shipped calibration (dummy.config.json):
  // frames turned to the portrait orientation the calibration belongs to (the device's software
  // transposes and mirrors: 90° clockwise), our line centres, our triangulation against its sheet
  // n·X = d (camera frame, mm), then X_platform = Rᵀ(X − t) turned by the table angle about z.
  // The turntable top is the plane z = 0 of that frame: the points on it measure the chain.
  const std::string dir = kData + "/laser/fabscanpi";
  REQUIRE_DATA(dir);
  std::ifstream in(dir + "/dummy.config.json");
  const nlohmann::json cfg = nlohmann::json::parse(in)["calibration"];
  const auto& Km = cfg["camera_matrix"];
  CameraIntrinsics cam{"fabscanpi", 1232, 1640, Km[0][0], Km[1][1], Km[0][2], Km[1][2], {0, 0, 0, 0, 0}};
  for (size_t i = 0; i < 5; ++i) cam.dist[i] = cfg["distortion_vector"][i];
  Plane sheet;
  for (int k = 0; k < 3; ++k) sheet.n[k] = cfg["laser_planes"][0]["normal"][k];
  sheet.d = -static_cast<double>(cfg["laser_planes"][0]["distance"]) * 1e-3;  // n·X = d mm → n·X + d' = 0 m
  Eigen::Matrix3d R;
  Eigen::Vector3d t;
  for (int r = 0; r < 3; ++r) {
    t[r] = static_cast<double>(cfg["platform_translation"][r]) * 1e-3;
    for (int c = 0; c < 3; ++c) R(r, c) = cfg["platform_rotation"][r][c];
  }
  const auto files = listImages({dir + "/scan_res1_laser1"});
  ASSERT_EQ(files.size(), 101u);
  std::vector<cv::Mat> frames;
  for (const auto& f : files) {
    cv::Mat img = cv::imread(f, cv::IMREAD_COLOR);
    ASSERT_FALSE(img.empty()) << f;
    cv::rotate(img, img, cv::ROTATE_90_CLOCKWISE);
    cv::cvtColor(img, img, cv::COLOR_BGR2RGB);
    frames.push_back(img);
  }
  struct Fit {
    size_t points = 0, table = 0;
    double rms_mm = 0, tilt_deg = 0, offset_mm = 0;
  };
  auto run = [&](LineExtractionConfig::Estimator estimator, bool distortion) {
    CameraIntrinsics c = cam;
    if (!distortion) c.dist = {0, 0, 0, 0, 0};  // as the device's own software computes
    const UndistortionMap map(c);
    LineExtractionConfig line;
    line.channel = 0;
    line.estimator = estimator;
    line.line_along_rows = false;  // column methods: the portrait frames' line runs along the columns
    std::vector<Eigen::Vector3d> table;
    Fit fit;
    for (size_t i = 0; i < frames.size(); ++i) {
      const Eigen::Matrix3d Rz =
          Eigen::AngleAxisd(static_cast<double>(i) * 3.6 * M_PI / 180, Eigen::Vector3d::UnitZ()).toRotationMatrix();
      for (const auto& p : triangulate(extractLine(frames[i], line), map, sheet)) {
        const Eigen::Vector3d q = Rz * (R.transpose() * (p.p - t));
        ++fit.points;
        if (std::abs(q.z()) < 0.003 && std::hypot(q.x(), q.y()) < 0.070) table.push_back(q);
      }
    }
    fit.table = table.size();
    if (table.size() < 3) return fit;
    const PlaneFit plane = fitPlane(table);  // the scanner's own flatness fit
    fit.rms_mm = plane.rms * 1e3;
    fit.tilt_deg = std::acos(std::min(1.0, std::abs(plane.normal.z()))) * 180 / M_PI;
    Eigen::Vector3d m = Eigen::Vector3d::Zero();
    for (const auto& q : table) m += q;
    fit.offset_mm = m.z() / static_cast<double>(table.size()) * 1e3;
    return fit;
  };
  const Fit ridge = run(LineExtractionConfig::Estimator::kRidge, true);
  const Fit ridge_nodist = run(LineExtractionConfig::Estimator::kRidge, false);
  const Fit cols = run(LineExtractionConfig::Estimator::kCentroid, true);
  for (const auto& [name, f] : {std::pair<const char*, const Fit&>{"ridge, shipped distortion", ridge},
                                {"ridge, no distortion (as the device)", ridge_nodist},
                                {"column centroid, shipped distortion", cols}}) {
    std::printf("fabscanpi end to end, %s: %zu points, %zu on the turntable (|z| < 3 mm, r < 70 mm): plane RMS %.3f mm, "
                "tilt %.2f deg, height %.3f mm\n", name, f.points, f.table, f.rms_mm, f.tilt_deg, f.offset_mm);
  }
  // The turntable comes out flat, level and at z = 0 of the device's own platform frame.
  EXPECT_GT(ridge.table, 30000u);
  EXPECT_LT(ridge.rms_mm, 1.2);
  EXPECT_LT(ridge.tilt_deg, 0.5);
  EXPECT_LT(std::abs(ridge.offset_mm), 1.5);
  EXPECT_GT(ridge.table, 3 * cols.table);  // the column method loses the table's steep traces
  EXPECT_LT(ridge.rms_mm, cols.rms_mm);
}
