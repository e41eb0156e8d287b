#include "cellsight/sim/calibration_captures.hpp"

#include <yaml-cpp/yaml.h>

#include <cmath>
#include <cstdio>
#include <memory>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <random>
#include <stdexcept>

#include "cellsight/common/file_io.hpp"
#include "cellsight/common/mesh.hpp"
#include "cellsight/common/yaml_reader.hpp"
#include "cellsight/sim/renderer.hpp"
#include "cellsight/sim/robot_model.hpp"

namespace cellsight {

namespace {

constexpr double kWhite = 0.85, kBlack = 0.08, kLight = 235.0;

/// Rays through the pixel corners of a camera (base frame), cached for many views.
class PlanarViewRenderer {
 public:
  PlanarViewRenderer(const Scene& scene, const CameraConfig& camera) : scene_(scene), camera_(camera) {
    const CameraIntrinsics& K = camera.intrinsics;
    w_ = K.width + 1;
    h_ = K.height + 1;
    rays_.resize(static_cast<size_t>(w_) * h_);
    const Eigen::Matrix3f R = camera.T_base_camera.linear().cast<float>();
    for (int v = 0; v < h_; ++v)
      for (int u = 0; u < w_; ++u)
        rays_[static_cast<size_t>(v) * w_ + u] =
            (R * K.pixelRay(Eigen::Vector2d(u - 0.5, v - 0.5)).cast<float>()).normalized();
    C_ = camera.T_base_camera.translation();
  }

  cv::Mat render(const Eigen::Isometry3d& T_base_board, const CalibrationCaptureConfig& b, uint64_t seed) const {
    const CameraIntrinsics& K = camera_.intrinsics;
    const Eigen::Isometry3d T_board_base = T_base_board.inverse();
    const Eigen::Vector3d n = T_base_board.linear().col(2), O = T_base_board.translation();
    const double sq = b.square;
    const double table_albedo = scene_.table.reflectivity;
    // albedo of what the ray d hits: the plate (pattern, white margin) or the table
    auto shade = [&](const Eigen::Vector3d& d) -> double {
      const double dn = n.dot(d);
      if (std::abs(dn) > 1e-12) {
        const double t = n.dot(O - C_) / dn;
        if (t > 0) {
          const Eigen::Vector3d q = T_board_base * (C_ + t * d);
          const double s = q.x() / sq, r = q.y() / sq;
          if (s >= -2 && s < b.board_cols + 1 && r >= -2 && r < b.board_rows + 1) {
            if (s < -1 || s >= b.board_cols || r < -1 || r >= b.board_rows) return kWhite;
            const int i = static_cast<int>(std::floor(s)) + 1, j = static_cast<int>(std::floor(r)) + 1;
            return (i + j) % 2 == 0 ? kBlack : kWhite;
          }
        }
      }
      if (d.z() < -1e-12) return table_albedo;
      return 0.0;
    };
    cv::Mat img(K.height, K.width, CV_32F);
    std::vector<float> corner(static_cast<size_t>(w_) * h_);
    for (size_t i = 0; i < rays_.size(); ++i) corner[i] = static_cast<float>(shade(rays_[i].cast<double>()));
    constexpr int kSub = 4;
    for (int v = 0; v < K.height; ++v) {
      float* row = img.ptr<float>(v);
      for (int u = 0; u < K.width; ++u) {
        const size_t i00 = static_cast<size_t>(v) * w_ + u, i01 = i00 + 1, i10 = i00 + w_, i11 = i10 + 1;
        const float a = corner[i00];
        if (a == corner[i01] && a == corner[i10] && a == corner[i11]) {
          row[u] = a;
          continue;
        }
        double sum = 0;
        for (int sy = 0; sy < kSub; ++sy)
          for (int sx = 0; sx < kSub; ++sx) {
            const float fx = (sx + 0.5f) / kSub, fy = (sy + 0.5f) / kSub;
            const Eigen::Vector3f d = (1 - fy) * ((1 - fx) * rays_[i00] + fx * rays_[i01]) +
                                      fy * ((1 - fx) * rays_[i10] + fx * rays_[i11]);
            sum += shade(d.normalized().cast<double>());
          }
        row[u] = static_cast<float>(sum / (kSub * kSub));
      }
    }
    img *= kLight;
    cv::GaussianBlur(img, img, cv::Size(0, 0), std::max(0.5, camera_.blur_sigma_px));
    if (scene_.noise.enabled && scene_.noise.sensor_sigma > 0) {
      cv::Mat noise(img.size(), CV_32F);
      cv::RNG rng(seed * 2654435761ull + 1);
      rng.fill(noise, cv::RNG::NORMAL, 0.0, scene_.noise.sensor_sigma);
      img += noise;
    }
    cv::Mat out;
    img.convertTo(out, CV_8U);  // rounds and saturates
    return out;
  }

 private:
  const Scene& scene_;
  const CameraConfig& camera_;
  int w_ = 0, h_ = 0;
  std::vector<Eigen::Vector3f> rays_;
  Eigen::Vector3d C_;
};

void writePng(const std::string& path, const cv::Mat& img) {
  std::vector<uchar> buf;
  if (!cv::imencode(".png", img, buf)) throw std::runtime_error(path + ": PNG encoding failed");
  writeFileAtomic(path, std::string(buf.begin(), buf.end()));
}

/// Board orientation lying face up: x along base x, y along -base y, z (into the board) down.
Eigen::Matrix3d faceUp() {
  Eigen::Matrix3d R;
  R.col(0) = Eigen::Vector3d::UnitX();
  R.col(1) = -Eigen::Vector3d::UnitY();
  R.col(2) = -Eigen::Vector3d::UnitZ();
  return R;
}

/// Board pose with its pattern centre at `centre`.
Eigen::Isometry3d boardAt(const Eigen::Matrix3d& R, const Eigen::Vector3d& centre, const CalibrationCaptureConfig& b) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = R;
  T.translation() = centre - R * Eigen::Vector3d((b.board_cols - 1) * b.square / 2, (b.board_rows - 1) * b.square / 2, 0);
  return T;
}

/// Whole plate in view (with a margin) and its printed side towards the camera.
bool boardInView(const CameraConfig& cam, const Eigen::Isometry3d& T_base_board, const CalibrationCaptureConfig& b,
                 double margin_px) {
  const Eigen::Isometry3d T_cam_board = cam.T_base_camera.inverse() * T_base_board;
  if ((T_cam_board.linear().col(2)).dot(T_cam_board.translation()) <= 0) return false;  // seen from behind
  const double sq = b.square;
  for (double s : {-2.0, b.board_cols + 1.0})
    for (double r : {-2.0, b.board_rows + 1.0}) {
      const Eigen::Vector3d p = T_cam_board * Eigen::Vector3d(s * sq, r * sq, 0);
      if (p.z() <= 0.05) return false;
      const Eigen::Vector2d uv = cam.intrinsics.project(p);
      if (uv.x() < margin_px || uv.y() < margin_px || uv.x() > cam.intrinsics.width - 1 - margin_px ||
          uv.y() > cam.intrinsics.height - 1 - margin_px)
        return false;
    }
  return true;
}

/// Flange pose with orientation R whose central beam (the drawn laser) hits `target`, flange at height h.
Eigen::Isometry3d aimBeam(const Eigen::Isometry3d& T_flange_laser, const Eigen::Matrix3d& R, const Eigen::Vector3d& target,
                          double h) {
  const Eigen::Vector3d tl = R * T_flange_laser.translation(), d = R * T_flange_laser.linear().col(2);
  if (d.z() > -0.2) throw std::runtime_error("calibration captures: the laser beam does not point down at the table");
  const double s = (target.z() - h - tl.z()) / d.z();
  Eigen::Isometry3d F = Eigen::Isometry3d::Identity();
  F.linear() = R;
  F.translation() = target - s * d - tl;
  return F;
}

void emitObservations(const std::string& path, const std::vector<std::string>& images,
                      const std::vector<Eigen::Isometry3d>& poses, double plane_z, double block_z) {
  YAML::Emitter out;
  out.SetDoublePrecision(17);
  out << YAML::BeginMap << YAML::Key << "observations" << YAML::Value << YAML::BeginSeq;
  for (size_t i = 0; i < images.size(); ++i) {
    out << YAML::BeginMap << YAML::Key << "image" << YAML::Value << images[i];
    out << YAML::Key << "flange_pose" << YAML::Value;
    emitPose(out, poses[i]);
    out << YAML::Key << "plane_z" << YAML::Value << plane_z;
    if (block_z != 0) out << YAML::Key << "block_z" << YAML::Value << block_z;
    out << YAML::EndMap;
  }
  out << YAML::EndSeq << YAML::EndMap;
  writeFileAtomic(path, std::string("# flange poses as the robot reported them\n") + out.c_str() + "\n");
}

}  // namespace

cv::Mat renderChessboardView(const Scene& scene, const CameraConfig& camera, const Eigen::Isometry3d& T_base_board,
                             const CalibrationCaptureConfig& board, uint64_t seed) {
  return PlanarViewRenderer(scene, camera).render(T_base_board, board, seed);
}

// Steps 1 and 2 for one camera: chessboard views for its intrinsics (under intrinsics_dir) and
// the board lying on the table at pattern_xy with its frame taught by the robot's pointer.
void writeCameraCaptures(const Scene& scene, const CameraConfig& cam, const CalibrationCaptureConfig& c, uint64_t seed,
                         const Eigen::Vector2d& pattern_xy, const std::string& intrinsics_dir,
                         const std::string& pattern_image, const std::string& taught) {
  const RobotErrorModel robot(scene.as_built.robot);
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const PlanarViewRenderer boards(scene, cam);

  // 1. Intrinsics: the board held in front of the camera, tilted 10-40 degrees, at 0-15 cm.
  int written = 0;
  for (int attempt = 0; written < c.intrinsic_views; ++attempt) {
    if (attempt > 200000) throw std::runtime_error("calibration captures: cannot place the board in the camera's view");
    const Eigen::Vector2d px(cam.intrinsics.width * (0.2 + 0.6 * U(rng)), cam.intrinsics.height * (0.2 + 0.6 * U(rng)));
    const double h = scene.table.z + 0.15 * U(rng);
    const Eigen::Vector3d d = cam.T_base_camera.linear() * cam.intrinsics.pixelRay(px);
    if (d.z() > -1e-3) continue;
    const Eigen::Vector3d centre = cam.T_base_camera.translation() + (h - cam.T_base_camera.translation().z()) / d.z() * d;
    const double yaw = 2 * M_PI * U(rng), tilt = (10 + 30 * U(rng)) * M_PI / 180, az = 2 * M_PI * U(rng);
    const Eigen::Matrix3d R = Eigen::AngleAxisd(tilt, Eigen::Vector3d(std::cos(az), std::sin(az), 0)).toRotationMatrix() *
                              Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() * faceUp();
    const Eigen::Isometry3d T = boardAt(R, centre, c);
    if (!boardInView(cam, T, c, 20)) continue;
    char name[64];
    std::snprintf(name, sizeof(name), "/view_%02d.png", written);
    writePng(intrinsics_dir + name, boards.render(T, c, seed * 1000 + written));
    ++written;
  }

  // 2. Camera pose: the board lying on the table (3 mm plate) in the middle of the workspace,
  //    its frame taught with the robot's pointer at three corners.
  const Eigen::Vector3d ws_centre(pattern_xy.x(), pattern_xy.y(), scene.table.z + 0.003);
  const Eigen::Isometry3d T_pattern =
      boardAt(Eigen::AngleAxisd(0.12, Eigen::Vector3d::UnitZ()).toRotationMatrix() * faceUp(), ws_centre, c);
  if (!boardInView(cam, T_pattern, c, 5)) throw std::runtime_error("calibration captures: the board on the table is not in the camera's view");
  writePng(pattern_image, boards.render(T_pattern, c, seed * 1000 + 999));
  std::normal_distribution<double> pointer(0.0, c.pointer_sigma_mm * 1e-3);
  auto teach = [&](const Eigen::Vector3d& corner) {
    Eigen::Isometry3d F = Eigen::Isometry3d::Identity();
    F.linear() = scene.robot.home.linear();
    const Eigen::Vector3d tcp(0, 0, c.tcp_length);
    F.translation() = corner - F.linear() * tcp;  // where the flange really is with the tip on the corner
    const Eigen::Vector3d reported = robot.reported(F) * tcp;
    return Eigen::Vector3d(reported + Eigen::Vector3d(pointer(rng), pointer(rng), pointer(rng)));
  };
  const double sq = c.square;
  const Eigen::Vector3d o = teach(T_pattern * Eigen::Vector3d(0, 0, 0));
  const Eigen::Vector3d x = teach(T_pattern * Eigen::Vector3d((c.board_cols - 1) * sq, 0, 0));
  const Eigen::Vector3d y = teach(T_pattern * Eigen::Vector3d(0, (c.board_rows - 1) * sq, 0));
  {
    YAML::Emitter out;
    out.SetDoublePrecision(17);
    out << YAML::BeginMap;
    for (const auto& [key, p] : {std::pair<const char*, Eigen::Vector3d>{"origin", o}, {"on_x", x}, {"in_xy", y}})
      out << YAML::Key << key << YAML::Value << YAML::Flow << YAML::BeginSeq << p.x() << p.y() << p.z() << YAML::EndSeq;
    out << YAML::EndMap;
    writeFileAtomic(taught, std::string("# the pattern's first inner corner, the last corner of its first row, the first "
                                          "corner of its last row, as the robot's pointer reported them (metres, base frame)\n") +
                                  out.c_str() + "\n");
  }

}

std::vector<Eigen::Isometry3d> handEyeFlangePoses(const Scene& scene, const CameraConfig& cam,
                                                  const Eigen::Isometry3d& Y, const std::vector<Eigen::Vector3d>& points,
                                                  int count, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0.0, 1.0);
  const Eigen::Vector3d axis = cam.T_base_camera.linear().col(2), C = cam.T_base_camera.translation();
  if (axis.z() > -0.2) throw std::runtime_error("hand-eye poses: the camera does not look down at the table");
  const Eigen::Vector3d centre = C + axis * ((scene.table.z - C.z()) / axis.z());
  Eigen::Matrix3d down;  // flange z down, x along base x
  down << 1, 0, 0, 0, -1, 0, 0, 0, -1;
  std::vector<Eigen::Isometry3d> flanges;
  Eigen::Isometry3d ref = Eigen::Isometry3d::Identity();
  ref.linear() = down;
  ref.translation() = centre + Eigen::Vector3d(0, 0, 0.25);
  flanges.push_back(ref);
  for (int a = 0; a < 3; ++a) {
    for (double s : {0.05, -0.05}) {
      Eigen::Isometry3d F = ref;
      F.translation()(a) += s;
      flanges.push_back(F);
    }
  }
  const Eigen::Isometry3d Xi = cam.T_base_camera.inverse();
  for (int attempt = 0; static_cast<int>(flanges.size()) < count; ++attempt) {
    if (attempt > 100000) throw std::runtime_error("hand-eye poses: cannot place the target in the camera's view");
    const double tilt = 25.0 * M_PI / 180 * U(rng), az = 2 * M_PI * U(rng), yaw = (U(rng) - 0.5) * M_PI / 2;
    Eigen::Isometry3d F = Eigen::Isometry3d::Identity();
    F.linear() = Eigen::AngleAxisd(tilt, Eigen::Vector3d(std::cos(az), std::sin(az), 0)).toRotationMatrix() *
                 Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() * down;
    F.translation() = centre + Eigen::Vector3d((U(rng) - 0.5) * 0.4, (U(rng) - 0.5) * 0.3, 0.1 + 0.25 * U(rng));
    const Eigen::Isometry3d T = Xi * F * Y;
    bool inside = T.linear().col(2).z() > 0.5;  // the target faces the camera
    for (const auto& p : points) {
      if (!inside) break;
      const Eigen::Vector3d q = T * p;
      if (q.z() < 0.1) {
        inside = false;
        break;
      }
      const Eigen::Vector2d uv = cam.intrinsics.project(q);
      inside = uv.x() > 30 && uv.y() > 30 && uv.x() < cam.intrinsics.width - 30 && uv.y() < cam.intrinsics.height - 30;
    }
    if (inside) flanges.push_back(F);
  }
  return flanges;
}

CalibrationCaptureFiles writeCalibrationCaptures(const Scene& scene, const std::string& dir,
                                                 const CalibrationCaptureConfig& c) {
  if (c.board_cols < 3 || c.board_rows < 3 || !(c.square > 0) || c.intrinsic_views < 3 || c.laser_views < 3)
    throw std::invalid_argument("calibration captures: board of at least 3x3 corners, square > 0, >= 3 views each");
  CalibrationCaptureFiles f;
  f.intrinsics_dir = dir + "/intrinsics";
  f.pattern_image = dir + "/extrinsics/pattern.png";
  f.taught = dir + "/extrinsics/taught.yaml";
  f.laser_obs = dir + "/laser/observations.yaml";
  f.three_point_obs = dir + "/laser_three_point/observations.yaml";
  f.board = std::to_string(c.board_cols) + "x" + std::to_string(c.board_rows);
  f.square = c.square;
  for (const char* sub : {"/intrinsics", "/extrinsics", "/laser", "/laser_three_point"}) makeDirs(dir + sub);

  writeCameraCaptures(scene, scene.scanner_camera, c, c.seed,
                      Eigen::Vector2d(scene.workspace.center().x(), scene.workspace.center().y()), f.intrinsics_dir,
                      f.pattern_image, f.taught);
  const RobotErrorModel robot(scene.as_built.robot);
  const Eigen::Vector3d ws_centre(scene.workspace.center().x(), scene.workspace.center().y(), scene.table.z + 0.003);

  // 3. Light sheet, least squares: the bare table seen from poses at several heights and tilts.
  Scene bare = scene;
  bare.objects.clear();
  bare.fixtures.clear();
  const Eigen::Isometry3d& drawn_laser = scene.as_built.drawn_laser;  // the user knows the drawing
  {
    const ScannerRenderer r(std::make_shared<CellGeometry>(bare));
    std::vector<std::string> images;
    std::vector<Eigen::Isometry3d> poses;
    const Eigen::Vector3d lo = scene.workspace.min(), sz = scene.workspace.sizes();
    for (int k = 0; k < c.laser_views; ++k) {
      const double fx = 0.2 + 0.6 * ((k % 3) / 2.0), fy = 0.2 + 0.6 * (((k / 3) % 4) / 3.0);
      const Eigen::Vector3d target(lo.x() + fx * sz.x(), lo.y() + fy * sz.y(), scene.table.z);
      const double h = scene.table.z + 0.20 + 0.10 * ((k * 7) % c.laser_views) / std::max(1, c.laser_views - 1);
      const double tilt_x = (k % 2 ? 1 : -1) * 0.08, tilt_y = ((k / 2) % 2 ? 1 : -1) * 0.05, yaw = 0.15 * std::sin(k);
      const Eigen::Matrix3d R = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()).toRotationMatrix() * scene.robot.home.linear() *
                                Eigen::AngleAxisd(tilt_x, Eigen::Vector3d::UnitX()).toRotationMatrix() *
                                Eigen::AngleAxisd(tilt_y, Eigen::Vector3d::UnitY()).toRotationMatrix();
      const Eigen::Isometry3d F = aimBeam(drawn_laser, R, target, h);
      const cv::Mat img = r.render(robot.actual(F, 100000 + static_cast<uint64_t>(k)), c.seed * 7777 + k);
      char name[64];
      std::snprintf(name, sizeof(name), "line_%02d.png", k);
      writePng(dir + "/laser/" + name, img);
      images.push_back(name);
      poses.push_back(F);
    }
    emitObservations(f.laser_obs, images, poses, scene.table.z, 0.0);
  }

  // 4. The thesis's three-point method: one view of the line over a gauge block on the table.
  {
    const double hb = c.gauge_block_height;
    SceneObject block;
    block.name = block.model = block.info.id = "gauge_block";
    block.info.mesh_file = dir + "/laser_three_point/gauge_block.ply";
    saveMeshPly(block.info.mesh_file, makeBox({0.05, 0.04, hb}));
    block.T_base_object = Eigen::Translation3d(ws_centre.x(), ws_centre.y(), scene.table.z + hb / 2);
    block.reflectivity = 0.6;
    bare.objects = {block};
    const ScannerRenderer r(std::make_shared<CellGeometry>(bare));
    const Eigen::Isometry3d F = aimBeam(drawn_laser, scene.robot.home.linear(),
                                        Eigen::Vector3d(ws_centre.x(), ws_centre.y(), scene.table.z + hb), scene.table.z + 0.26);
    writePng(dir + "/laser_three_point/line.png", r.render(robot.actual(F, 200000), c.seed * 7777 + 999));
    emitObservations(f.three_point_obs, {"line.png"}, {F}, scene.table.z, scene.table.z + hb);
  }
  // 5. The fixture camera (scenes with QR fixtures): its own chessboard views, and the board on
  //    the table under the camera's optical axis, taught like the scanner camera's.
  if (!scene.fixtures.empty()) {
    f.fixture_intrinsics_dir = dir + "/fixture_intrinsics";
    f.fixture_pattern_image = dir + "/fixture_extrinsics/pattern.png";
    f.fixture_taught = dir + "/fixture_extrinsics/taught.yaml";
    makeDirs(f.fixture_intrinsics_dir);
    makeDirs(dir + "/fixture_extrinsics");
    const CameraConfig& fc = scene.fixture_camera;
    const Eigen::Vector3d axis = fc.T_base_camera.linear().col(2), C = fc.T_base_camera.translation();
    if (axis.z() > -0.2) throw std::runtime_error("calibration captures: the fixture camera does not look down at the table");
    const Eigen::Vector3d on_table = C + axis * ((scene.table.z - C.z()) / axis.z());
    CalibrationCaptureConfig big = c;  // the fixture camera sees a wider field: a larger board
    big.square = c.fixture_square;
    f.fixture_square = c.fixture_square;
    writeCameraCaptures(scene, fc, big, c.seed * 31 + 17, on_table.head<2>(), f.fixture_intrinsics_dir,
                        f.fixture_pattern_image, f.fixture_taught);
    // 6. Fixture camera to robot (eye-to-hand): a board on top of the tool, printed side up,
    //    carried through the camera's view; the flange poses as the robot reported them, and the
    //    pointer's touch of the board's origin in the first (reference) pose for the axes method
    f.hand_eye_dir = dir + "/hand_eye";
    f.hand_eye_square = c.hand_eye_square;
    makeDirs(f.hand_eye_dir);
    CalibrationCaptureConfig tool = c;
    tool.square = c.hand_eye_square;
    Eigen::Isometry3d Y = Eigen::Isometry3d::Identity();  // board origin: first inner corner
    Y.translation() = Eigen::Vector3d(-(c.board_cols - 1) * tool.square / 2, -(c.board_rows - 1) * tool.square / 2, -0.06);
    std::vector<Eigen::Vector3d> corners;
    for (int r = 0; r < c.board_rows; ++r)
      for (int k = 0; k < c.board_cols; ++k) corners.emplace_back(k * tool.square, r * tool.square, 0.0);
    const auto flanges = handEyeFlangePoses(scene, fc, Y, corners, std::max(8, c.hand_eye_views), c.seed * 53 + 5);
    const PlanarViewRenderer tool_boards(scene, fc);
    YAML::Emitter poses;
    poses.SetDoublePrecision(17);
    poses << YAML::BeginMap << YAML::Key << "axes_reference" << YAML::Value << 0;
    poses << YAML::Key << "axes_moves" << YAML::Value << YAML::Flow << YAML::BeginSeq << 1 << 2 << 3 << 4 << 5 << 6
          << YAML::EndSeq;
    poses << YAML::Key << "views" << YAML::Value << YAML::BeginSeq;
    Eigen::Isometry3d reference_actual = Eigen::Isometry3d::Identity();
    for (size_t k = 0; k < flanges.size(); ++k) {
      const Eigen::Isometry3d actual = robot.actual(flanges[k], 300000 + k);
      if (k == 0) reference_actual = actual;
      char name[64];
      std::snprintf(name, sizeof(name), "view_%02zu.png", k);
      writePng(f.hand_eye_dir + "/" + name, tool_boards.render(actual * Y, tool, c.seed * 4241 + k));
      poses << YAML::BeginMap << YAML::Key << "image" << YAML::Value << name << YAML::Key << "flange" << YAML::Value;
      emitPose(poses, flanges[k]);
      poses << YAML::EndMap;
    }
    poses << YAML::EndSeq << YAML::EndMap;
    writeFileAtomic(f.hand_eye_dir + "/flange_poses.yaml",
                    std::string("# fixture camera to robot: flange poses as the robot reported them (metres, base frame), "
                                "one per image; views 1-6 are pure moves along the base axes from view 0\n") +
                        poses.c_str() + "\n");
    // the pointer on the board's origin with the board held in the reference pose
    std::normal_distribution<double> pointer(0.0, c.pointer_sigma_mm * 1e-3);
    const Eigen::Vector3d origin = (reference_actual * Y).translation();
    Eigen::Isometry3d P = Eigen::Isometry3d::Identity();
    P.linear() = scene.robot.home.linear();
    const Eigen::Vector3d tcp(0, 0, c.tcp_length);
    P.translation() = origin - P.linear() * tcp;
    std::mt19937_64 touch_rng(c.seed * 97 + 3);
    const Eigen::Vector3d touched = robot.reported(P) * tcp + Eigen::Vector3d(pointer(touch_rng), pointer(touch_rng), pointer(touch_rng));
    YAML::Emitter t;
    t.SetDoublePrecision(17);
    t << YAML::BeginMap << YAML::Key << "origin" << YAML::Value << YAML::Flow << YAML::BeginSeq << touched.x() << touched.y()
      << touched.z() << YAML::EndSeq << YAML::EndMap;
    writeFileAtomic(f.hand_eye_dir + "/touched.yaml",
                    std::string("# the board's first inner corner in view 0, touched with the robot's pointer (metres, base frame)\n") +
                        t.c_str() + "\n");
  }
  return f;
}

}  // namespace cellsight
