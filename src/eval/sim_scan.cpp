#include "cellsight/eval/sim_scan.hpp"

#include "cellsight/common/errors.hpp"

#include <chrono>
#include <cmath>

namespace cellsight {

ScannerCalibration scannerCalibrationOf(const Scene& s) {
  ScannerCalibration c;
  c.intrinsics = s.scanner_camera.intrinsics;
  c.T_base_camera = s.scanner_camera.T_base_camera;
  c.T_flange_laser = s.laser.T_flange_laser;
  c.undistortion = std::make_shared<UndistortionMap>(c.intrinsics);
  return c;
}

ScanCloud simulateScan(const ScannerRenderer& renderer,
                       const std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>>& poses,
                       const ScannerCalibration& cal, const LineExtractionConfig& line,
                       const TriangulationConfig& tri, uint64_t seed, SimScanStats* stats,
                       const RobotErrorModel* robot) {
  ScanCloud cloud;
  SimScanStats st;
  using clock = std::chrono::steady_clock;
  for (size_t i = 0; i < poses.size(); ++i) {
    const auto t0 = clock::now();
    // the robot is told (and reports) poses[i]; the flange really goes to `actual`
    const uint64_t frame_seed = seed * 1000003ull + i;
    const Eigen::Isometry3d actual = robot ? robot->actual(poses[i], frame_seed) : poses[i];
    const cv::Mat img = renderer.render(actual, frame_seed);
    const auto t1 = clock::now();
    addProfile(img, poses[i], cal, line, tri, cloud, &st.line);
    st.render_seconds += std::chrono::duration<double>(t1 - t0).count();
    st.process_seconds += std::chrono::duration<double>(clock::now() - t1).count();
    ++st.frames;
  }
  if (stats) *stats = st;
  return cloud;
}

/// Flange poses sweeping the light line across `target` with the flange turned by `yaw` about
/// the vertical: the sheet's horizontal normal sets the sweep direction.
std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>> sweepAcross(const Scene& s, const Eigen::Vector3d& target, double yaw, double half_span,
                  double step, double flange_height) {
  const Eigen::Isometry3d base_rot(s.robot.home.linear());
  Eigen::Isometry3d F0 = Eigen::Isometry3d::Identity();
  F0.linear() = Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * base_rot.linear();
  F0.translation() = Eigen::Vector3d(0, 0, flange_height);
  const Eigen::Isometry3d L = F0 * s.laser.T_flange_laser;
  // Where the central beam meets the horizontal plane through the target.
  const Eigen::Vector3d e = L.translation(), z = L.linear().col(2);
  const double t = (target.z() - e.z()) / z.z();
  const Eigen::Vector3d hit = e + t * z;
  Eigen::Vector3d sweep = L.linear().col(1);
  sweep.z() = 0;
  sweep.normalize();
  std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>> poses;
  const int n = static_cast<int>(std::round(2 * half_span / step)) + 1;
  for (int i = 0; i < n; ++i) {
    const double sdist = -half_span + i * step;
    Eigen::Isometry3d F = F0;
    F.translation() += Eigen::Vector3d(target.x() - hit.x(), target.y() - hit.y(), 0) + sdist * sweep;
    poses.push_back(F);
  }
  return poses;
}

SphereAcceptance sphereAcceptance(const ScannerRenderer& renderer, const SceneObject& sphere,
                                  const ScannerCalibration& cal, const LineExtractionConfig& line,
                                  const TriangulationConfig& tri, int K, double step, bool filter,
                                  const RobotErrorModel* robot) {
  const Scene& scene = renderer.geometry().scene();
  const TriangleMesh mesh = loadValidMesh(sphere.info.mesh_file);
  SphereAcceptance out;
  out.true_center = sphere.T_base_object * mesh.bounds().center().cast<double>();
  out.true_radius = 0.5 * static_cast<double>(mesh.bounds().sizes().x());
  std::vector<Eigen::Vector3d> centres;
  for (int k = 0; k < K; ++k) {
    const double yaw = 2 * M_PI * k / K;
    const auto poses = sweepAcross(scene, out.true_center, yaw, out.true_radius + 0.004, step,
                                   scene.robot.home.translation().z());
    ScanCloud c = simulateScan(renderer, poses, cal, line, tri, scene.noise.seed + 100 + static_cast<uint64_t>(k), nullptr,
                               robot);
    if (filter) c = statisticalOutlierRemoval(c, 20, 3.0);
    std::vector<Eigen::Vector3d> pts;
    for (const auto& p : c.points) {
      const Eigen::Vector3d q = p.cast<double>();
      if ((q - out.true_center).norm() < out.true_radius + 0.003 && q.z() > scene.table.z + 0.002) pts.push_back(q);
    }
    const SphereFit f = fitSphere(pts);
    out.fits.push_back(f);
    out.frames.push_back(poses.size());
    centres.push_back(f.center);
    out.mpe_p_worst = std::max(out.mpe_p_worst, f.max_abs_dev);
  }
  out.mpe_p = out.fits.empty() ? 0 : out.fits[0].max_abs_dev;
  out.mpe_al = minimumEnclosingDiameter(centres);
  return out;
}

}  // namespace cellsight
