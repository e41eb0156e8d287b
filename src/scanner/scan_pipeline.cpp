#include "cellsight/scanner/scan_pipeline.hpp"

#include <cmath>
#include <stdexcept>

#include "cellsight/common/calibration.hpp"
#include "cellsight/common/errors.hpp"

namespace cellsight {

ScannerCalibration ScannerCalibration::fromFolder(const std::string& dir, const std::string& camera_frame,
                                                  const std::string& laser_frame, const std::string& camera_name) {
  const CalibrationSet set = loadCalibrationFolder(dir);
  ScannerCalibration c;
  bool cam = false, pose = false, laser = false;
  for (const auto& [file, t] : set.transforms) {
    if (t.child_frame == camera_frame) {
      c.T_base_camera = t.T_parent_child;
      pose = true;
    } else if (t.child_frame == laser_frame) {
      c.T_flange_laser = t.T_parent_child;
      laser = true;
    }
  }
  for (const std::string& f : set.camera_files) {
    const CameraIntrinsics k = loadCameraInfoYaml(f);
    if (k.camera_name == camera_name || set.camera_files.size() == 1) {
      c.intrinsics = k;
      cam = true;
    }
  }
  std::string missing;
  if (!cam) missing += " camera intrinsics (camera_name " + camera_name + ")";
  if (!pose) missing += " camera pose (child frame " + camera_frame + ")";
  if (!laser) missing += " light sheet (child frame " + laser_frame + ")";
  if (!missing.empty()) throw ConfigError(dir + ": the scanner calibration lacks" + missing);
  c.undistortion = std::make_shared<UndistortionMap>(c.intrinsics);
  return c;
}

bool lineAlongRows(const Plane& plane_camera) {
  return std::abs(plane_camera.n.y()) >= std::abs(plane_camera.n.x());
}

namespace {
void addStats(const LineExtractionStats& s, LineExtractionStats* sum) {
  sum->scanned += s.scanned;
  sum->found += s.found;
  sum->no_line += s.no_line;
  sum->ambiguous += s.ambiguous;
  sum->too_wide += s.too_wide;
  sum->edge += s.edge;
  sum->saturated += s.saturated;
  sum->segments += s.segments;
  sum->not_ridge += s.not_ridge;
  sum->background = s.background;
}
}  // namespace

size_t addFrameProfile(const cv::Mat& image, const Plane& plane_camera, const Eigen::Isometry3d& T_base_camera,
                       const UndistortionMap& undistortion, LineExtractionConfig line, const TriangulationConfig& tri,
                       ScanCloud& cloud, LineExtractionStats* stats) {
  line.line_along_rows = lineAlongRows(plane_camera);
  LineExtractionStats st;
  const auto pts = extractLine(image, line, &st);
  const auto profile = triangulate(pts, undistortion, plane_camera, tri);
  for (const auto& pp : profile) cloud.append((T_base_camera * pp.p).cast<float>(), pp.intensity);
  if (stats) addStats(st, stats);
  return profile.size();
}

size_t addProfile(const cv::Mat& image, const Eigen::Isometry3d& T_base_flange, const ScannerCalibration& cal,
                  const LineExtractionConfig& line, const TriangulationConfig& tri, ScanCloud& cloud,
                  LineExtractionStats* stats) {
  if (!cal.undistortion)
    throw std::invalid_argument("addProfile: the scanner calibration has no undistortion map (make it with fromFolder)");
  const Plane plane = laserPlane(cal.T_base_camera.inverse() * T_base_flange * cal.T_flange_laser);
  return addFrameProfile(image, plane, cal.T_base_camera, *cal.undistortion, line, tri, cloud, stats);
}

ScanCloud finishScan(const ScanCloud& raw, const ScannerSettings& settings, const Eigen::Vector3f& viewpoint) {
  ScanCloud cloud = settings.has_workspace ? cropBox(raw, settings.workspace) : raw;
  if (settings.outlier_k > 0) cloud = statisticalOutlierRemoval(cloud, settings.outlier_k, settings.outlier_std);
  if (settings.normal_k > 0 && cloud.size() > static_cast<size_t>(settings.normal_k))
    estimateNormals(cloud, settings.normal_k, viewpoint);
  cloud.frame_id = raw.frame_id;
  return cloud;
}

}  // namespace cellsight
