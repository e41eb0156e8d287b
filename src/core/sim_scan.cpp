#include "cellsight/sim_scan.hpp"

#include <chrono>

namespace cellsight {

ScannerCalibration ScannerCalibration::fromScene(const Scene& s) {
  ScannerCalibration c;
  c.intrinsics = s.scanner_camera.intrinsics;
  c.T_base_camera = s.scanner_camera.T_base_camera;
  c.T_flange_laser = s.laser.T_flange_laser;
  c.reference_z = s.table.z;
  c.undistortion = std::make_shared<UndistortionMap>(c.intrinsics);
  return c;
}

bool lineAlongRows(const Eigen::Isometry3d& T_base_flange, const ScannerCalibration& cal) {
  const Plane sheet = laserPlane(T_base_flange * cal.T_flange_laser);
  Eigen::Vector3d dir = sheet.n.cross(Eigen::Vector3d::UnitZ());
  if (dir.norm() < 1e-6) return true;  // sheet parallel to the support plane: no trace
  dir.normalize();
  // A point on both planes: the sheet point closest to the laser origin's vertical foot.
  const Eigen::Vector3d o = (T_base_flange * cal.T_flange_laser).translation();
  Eigen::Vector3d q(o.x(), o.y(), cal.reference_z);
  const Eigen::Vector3d in_plane = sheet.n - sheet.n.z() * Eigen::Vector3d::UnitZ();
  q -= sheet.distance(q) / in_plane.squaredNorm() * in_plane;
  const Eigen::Isometry3d T_cam_base = cal.T_base_camera.inverse();
  const Eigen::Vector2d a = cal.intrinsics.project(T_cam_base * q);
  const Eigen::Vector2d b = cal.intrinsics.project(T_cam_base * (q + 0.01 * dir));
  return std::abs(b.x() - a.x()) >= std::abs(b.y() - a.y());
}

void addProfile(const cv::Mat& image, const Eigen::Isometry3d& T_base_flange,
                const ScannerCalibration& cal, const LineExtractionConfig& line,
                const TriangulationConfig& tri, ScanCloud& cloud, LineExtractionStats* stats,
                bool auto_direction) {
  LineExtractionStats st;
  LineExtractionConfig lc = line;
  if (auto_direction) lc.line_along_rows = lineAlongRows(T_base_flange, cal);
  const auto pts = extractLine(image, lc, &st);
  const Plane plane = laserPlane(cal.T_base_camera.inverse() * T_base_flange * cal.T_flange_laser);
  const auto profile = cal.undistortion ? triangulate(pts, *cal.undistortion, plane, tri)
                                        : triangulate(pts, cal.intrinsics, plane, tri);
  for (const auto& pp : profile) {
    cloud.append((cal.T_base_camera * pp.p).cast<float>(), pp.intensity);
  }
  if (stats) {
    stats->scanned += st.scanned;
    stats->found += st.found;
    stats->no_line += st.no_line;
    stats->ambiguous += st.ambiguous;
    stats->too_wide += st.too_wide;
    stats->edge += st.edge;
    stats->saturated += st.saturated;
    stats->background = st.background;
  }
}

ScanCloud simulateScan(const ScannerRenderer& renderer,
                       const std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>>& poses,
                       const ScannerCalibration& cal, const LineExtractionConfig& line,
                       const TriangulationConfig& tri, uint64_t seed, SimScanStats* stats) {
  ScanCloud cloud;
  SimScanStats st;
  using clock = std::chrono::steady_clock;
  for (size_t i = 0; i < poses.size(); ++i) {
    const auto t0 = clock::now();
    const cv::Mat img = renderer.render(poses[i], seed * 1000003ull + i);
    const auto t1 = clock::now();
    addProfile(img, poses[i], cal, line, tri, cloud, &st.line);
    st.render_seconds += std::chrono::duration<double>(t1 - t0).count();
    st.process_seconds += std::chrono::duration<double>(clock::now() - t1).count();
    ++st.frames;
  }
  if (stats) *stats = st;
  return cloud;
}

}  // namespace cellsight
