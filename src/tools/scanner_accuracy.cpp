// Scanner acceptance figures (thesis §1, after CMM tests):
//   sim:   scans the simulated scene in-process with the scanner's own extraction and
//          triangulation; reports the distance of scan points to the true surfaces, MPE_P on the
//          reference sphere (one motion), MPE_AL (K sphere scans with different projector
//          orientations; diameter of the smallest sphere holding the K fitted centres) and the
//          flatness of a bare table patch.
//   scan:  a scan made elsewhere (the ROS demo) against the scene's truth, with --k the
//          in-process K-orientation sphere scans for MPE_AL.
//   frames: a recorded scan (frames.json + PNGs) triangulated again with a given calibration
//          (and optionally the simulator's true flange poses): the error budget of a scan.
//   calibration: a calibration folder against the truth, and the robot's absolute error.
//   compare: two clouds of the same scan (live, replayed): exit 0 when the same within a tolerance.
//   cloud: MPE_P / sphere fit on any PLY/PCD cloud near a given centre (real data).
// Output: JSON on stdout and, with --json FILE, written atomically.
// Usage: cellsight_scanner_accuracy sim --scene S.yaml --trajectories T.yaml [--trajectory demo_sweep|none]
//          [--no-noise] [--estimator ridge|centroid|gaussian3|run_centre] [--centroid-floor F]
//          [--background-percentile P] [--smoothing-degree N] [--sphere-model sphere25] [--k 5]
//          [--sphere-step-mm 0.5] [--no-filter] [--ply scan.ply] [--json out.json]
//        cellsight_scanner_accuracy scan --scene S.yaml --cloud scan.ply [--k 5] [--sphere-model sphere25]
//          [--json out.json]
//        cellsight_scanner_accuracy frames --frames frames.json --calibration DIR [--flange-truth F.jsonl]
//          [--scanner-config config/scanner.yaml] [--scene S.yaml] [--ply out.ply] [--json out.json]
//        cellsight_scanner_accuracy compare --a live.ply --b replay.ply [--tolerance-m 1e-6]
//        cellsight_scanner_accuracy cloud --cloud scan.ply --center x,y,z [--radius-mm 12.5] [--margin-mm 3]
//          [--json out.json]
//        (--help on the tool and on each subcommand.) Bad or unknown options are reported by CLI11
//        (non-zero exit); failures at run time print "error: ..." and exit 1.
#include <algorithm>
#include <cmath>
#include <iostream>
#include <nlohmann/json.hpp>
#include <numeric>
#include <fstream>
#include <map>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>
#include <tuple>

#include "cli_args.hpp"
#include "json_pose.hpp"
#include "cellsight/scanner/accuracy.hpp"
#include "cellsight/eval/evaluation.hpp"
#include "cellsight/common/file_io.hpp"
#include "cellsight/common/image_io.hpp"
#include "cellsight/eval/sim_scan.hpp"
#include "cellsight/common/trajectory.hpp"
#include "cellsight/scanner/scanner_config.hpp"

using namespace cellsight;

namespace {

/// The options of one subcommand (each has its own instance).
struct Options {
  std::string scene, trajectories, trajectory = "demo_sweep", estimator = "ridge";
  std::string sphere_model = "sphere25", ply, json, cloud, a, b;
  std::string frames, calibration, flange_truth, scanner_config = "config/scanner.yaml", line_settings;
  bool estimator_given = false;
  bool no_noise = false, no_filter = false;
  LineExtractionConfig line;  // --centroid-floor, --background-percentile, --smoothing-degree
  int k = 5;
  bool k_given = false;
  double sphere_step_mm = 0.5, tolerance_m = 1e-6, radius_mm = 12.5, margin_mm = 3;
  std::vector<double> center;
};

std::vector<Eigen::Vector3d> toDouble(const ScanCloud& c) {
  std::vector<Eigen::Vector3d> out;
  for (const auto& p : c.points) out.push_back(p.cast<double>());
  return out;
}

std::vector<Eigen::Vector3d> near(const ScanCloud& c, const Eigen::Vector3d& center, double radius) {
  std::vector<Eigen::Vector3d> out;
  for (const auto& p : c.points) {
    if ((p.cast<double>() - center).norm() < radius) out.push_back(p.cast<double>());
  }
  return out;
}

nlohmann::json sphereJson(const SphereFit& f) {
  return {{"points", f.points},
          {"center_m", {f.center.x(), f.center.y(), f.center.z()}},
          {"radius_mm", f.radius * 1e3},
          {"rms_mm", f.rms * 1e3},
          {"mpe_p_mm", f.max_abs_dev * 1e3},
          {"form_range_mm", f.form_range * 1e3}};
}

int runSim(const Options& o) {
  Scene scene = loadScene(o.scene);
  if (o.no_noise) scene.noise.enabled = false;
  LineExtractionConfig line = o.line;
  if (!o.line_settings.empty()) line = loadScannerSettings(o.line_settings).line;  // as the node reads them
  if (o.line_settings.empty() || o.estimator_given) line.estimator = LineExtractionConfig::parseEstimator(o.estimator);
  TriangulationConfig tri;
  auto geometry = std::make_shared<CellGeometry>(scene);
  ScannerRenderer renderer(geometry);
  const ScannerCalibration cal = scannerCalibrationOf(scene);
  const Eigen::AlignedBox3f ws(scene.workspace.min().cast<float>() - Eigen::Vector3f::Constant(0.002f),
                               scene.workspace.max().cast<float>() + Eigen::Vector3f::Constant(0.002f));
  nlohmann::json out;
  out["scene"] = scene.file;
  out["noise"] = scene.noise.enabled;
  out["estimator"] = o.estimator;

  // 1. The whole scene along a named trajectory: surface error vs truth.
  const std::string& traj_name = o.trajectory;
  if (traj_name != "none") {
    if (o.trajectories.empty()) throw std::invalid_argument("--trajectories is required unless --trajectory none");
    const auto trajectories = loadTrajectories(o.trajectories);
    if (!trajectories.count(traj_name))
      throw std::invalid_argument("--trajectory: '" + traj_name + "' not found in " + o.trajectories);
    const Trajectory& traj = trajectories.at(traj_name);
    SimScanStats st;
    ScanCloud raw = simulateScan(renderer, traj.poses, cal, line, tri, scene.noise.seed, &st);
    ScanCloud cloud = cropBox(raw, ws);
    if (!o.no_filter) cloud = statisticalOutlierRemoval(cloud, 20, 3.0);
    const SurfaceErrorStats e = SurfaceDistance(scene).stats(toDouble(cloud));
    out["scan"] = {{"trajectory", traj_name},
                   {"frames", st.frames},
                   {"points_raw", raw.size()},
                   {"points", cloud.size()},
                   {"columns_with_line_share", static_cast<double>(st.line.found) / std::max(1, st.line.scanned)},
                   {"ambiguous_columns", st.line.ambiguous},
                   {"surface_error_rms_mm", e.rms * 1e3},
                   {"surface_error_max_mm", e.max * 1e3},
                   {"surface_error_p99_mm", e.p99 * 1e3},
                   {"surface_error_mean_mm", e.mean_abs * 1e3},
                   {"render_ms_per_frame", 1e3 * st.render_seconds / std::max<size_t>(1, st.frames)},
                   {"process_ms_per_frame", 1e3 * st.process_seconds / std::max<size_t>(1, st.frames)}};
    if (!o.ply.empty()) saveCloud(o.ply, cloud);
  }

  // 2. Reference sphere: K scans with the projector turned by 360°/K each.
  const SceneObject* sphere = nullptr;
  for (const auto& obj : scene.objects) {
    if (obj.model == o.sphere_model) sphere = &obj;
  }
  if (sphere) {
    const int K = o.k;
    const double step = o.sphere_step_mm * 1e-3;
    const SphereAcceptance acc = sphereAcceptance(renderer, *sphere, cal, line, tri, K, step, !o.no_filter);
    nlohmann::json scans = nlohmann::json::array();
    for (int k = 0; k < K; ++k) {
      nlohmann::json j = sphereJson(acc.fits[static_cast<size_t>(k)]);
      j["yaw_deg"] = 360.0 * k / K;
      j["frames"] = acc.frames[static_cast<size_t>(k)];
      j["center_error_mm"] = (acc.fits[static_cast<size_t>(k)].center - acc.true_center).norm() * 1e3;
      scans.push_back(j);
    }
    out["sphere"] = {{"true_center_m", {acc.true_center.x(), acc.true_center.y(), acc.true_center.z()}},
                     {"true_radius_mm", acc.true_radius * 1e3},
                     {"k", K},
                     {"scans", scans},
                     {"mpe_p_mm", acc.mpe_p * 1e3},
                     {"mpe_p_worst_of_k_mm", acc.mpe_p_worst * 1e3},
                     {"mpe_al_mm", acc.mpe_al * 1e3}};
  }

  // 3. Flatness of a bare table patch (in front of the parts).
  {
    // A patch of bare table: the first candidate with no object within 20 mm.
    Eigen::Vector3d target(scene.workspace.center().x(), scene.workspace.min().y() + 0.015, scene.table.z);
    for (double fx = 0.1; fx < 0.95; fx += 0.05) {
      for (double fy : {0.06, 0.5, 0.94}) {
        const Eigen::Vector3d cand = scene.workspace.min() + Eigen::Vector3d(fx, fy, 0).cwiseProduct(scene.workspace.sizes());
        bool clear = true;
        for (const auto& obj : scene.objects) {
          Eigen::AlignedBox3d b;
          const TriangleMesh m = loadValidMesh(obj.info.mesh_file);
          for (const auto& v : m.vertices) b.extend(obj.T_base_object * v.cast<double>());
          const Eigen::Vector3d lo(b.min().x() - 0.045, b.min().y() - 0.03, -1), hi(b.max().x() + 0.045, b.max().y() + 0.03, 1);
          if (Eigen::AlignedBox3d(lo, hi).contains(Eigen::Vector3d(cand.x(), cand.y(), 0))) clear = false;
        }
        if (clear) {
          target = Eigen::Vector3d(cand.x(), cand.y(), scene.table.z);
          fx = 1;
          break;
        }
      }
    }
    const auto poses = sweepAcross(scene, target, 0, 0.010, 0.001, scene.robot.home.translation().z());
    ScanCloud c = simulateScan(renderer, poses, cal, line, tri, scene.noise.seed + 7);
    if (!o.no_filter) c = statisticalOutlierRemoval(c, 20, 3.0);
    std::vector<Eigen::Vector3d> pts;
    for (const auto& p : c.points) {
      if (std::abs(p.x() - target.x()) < 0.02 && std::abs(p.y() - target.y()) < 0.008 &&
          std::abs(p.z() - scene.table.z) < 0.001)
        pts.push_back(p.cast<double>());
    }
    const PlaneFit pf = fitPlane(pts);
    out["flatness"] = {{"patch_center_m", {target.x(), target.y(), target.z()}},
                       {"points", pts.size()}, {"rms_mm", pf.rms * 1e3}, {"flatness_mm", pf.flatness * 1e3}};
  }
  std::cout << out.dump(2) << "\n";
  if (!o.json.empty()) writeFileAtomic(o.json, out.dump(2) + "\n");
  return 0;
}

// A scan made elsewhere (the ROS demo) against the scene's truth, plus, with --k, the
// in-process K-orientation sphere scans for MPE_AL.
/// Surface error against the scene's truth and MPE_P on the reference sphere in the cloud.
nlohmann::json scanFigures(const Scene& scene, const ScanCloud& cloud, const std::string& sphere_model) {
  std::vector<Eigen::Vector3d> pts = toDouble(cloud);
  const SurfaceErrorStats e = SurfaceDistance(scene).stats(pts);
  nlohmann::json out;
  out["points"] = cloud.size();
  out["surface_error_rms_mm"] = e.rms * 1e3;
  out["surface_error_max_mm"] = e.max * 1e3;
  out["surface_error_p99_mm"] = e.p99 * 1e3;
  out["surface_error_mean_mm"] = e.mean_abs * 1e3;
  for (const auto& obj : scene.objects) {
    if (obj.model != sphere_model) continue;
    const TriangleMesh mesh = loadValidMesh(obj.info.mesh_file);
    const Eigen::Vector3d center = obj.T_base_object * mesh.bounds().center().cast<double>();
    const double radius = 0.5 * mesh.bounds().sizes().x();
    std::vector<Eigen::Vector3d> sp;
    for (const auto& p : near(cloud, center, radius + 0.003)) {
      if (p.z() > scene.table.z + 0.002) sp.push_back(p);
    }
    const SphereFit f = fitSphere(sp);
    out["sphere_in_scan"] = sphereJson(f);
    out["mpe_p_mm"] = f.max_abs_dev * 1e3;
  }
  return out;
}

int runScan(const Options& o) {
  const Scene scene = loadScene(o.scene);
  const ScanCloud cloud = loadCloud(o.cloud);
  nlohmann::json out = scanFigures(scene, cloud, o.sphere_model);
  if (o.k_given) {
    Scene s = scene;
    LineExtractionConfig line;
    ScannerRenderer renderer(std::make_shared<CellGeometry>(s));
    // the sweeps use the given calibration (default: the truth) with the robot as built
    const ScannerCalibration cal =
        o.calibration.empty() ? scannerCalibrationOf(s) : ScannerCalibration::fromFolder(o.calibration);
    const RobotErrorModel robot(s.as_built.robot);
    for (const auto& obj : s.objects) {
      if (obj.model != o.sphere_model) continue;
      const SphereAcceptance acc = sphereAcceptance(renderer, obj, cal, line, {}, o.k, 0.5e-3, true, &robot);
      out["mpe_al_mm"] = acc.mpe_al * 1e3;
      out["mpe_p_dedicated_sweep_mm"] = acc.mpe_p * 1e3;
      out["mpe_al_k"] = o.k;
      out["mpe_al_method"] = "K in-process sphere sweeps (same extraction and triangulation as the nodes), projector turned 360/K apart";
    }
  }
  std::cout << out.dump(2) << "\n";
  if (!o.json.empty()) writeFileAtomic(o.json, out.dump(2) + "\n");
  return 0;
}

/// A recorded scan (frames.json + PNGs of camera_trigger) triangulated again in-process with a
/// given calibration, optionally with the flange poses the simulator knows to be true
/// (frames_truth.jsonl, matched by stamp): the same extraction, triangulation, crop and
/// outlier filter as the nodes (config/scanner.yaml).
int runFrames(const Options& o) {
  std::ifstream f(o.frames);
  if (!f) throw std::runtime_error("cannot read --frames '" + o.frames + "'");
  nlohmann::json frames;
  try {
    f >> frames;
  } catch (const std::exception& e) {
    throw std::runtime_error(o.frames + ": not valid JSON: " + e.what());
  }
  std::map<int64_t, Eigen::Isometry3d> true_flange;
  if (!o.flange_truth.empty()) {
    std::ifstream t(o.flange_truth);
    if (!t) throw std::runtime_error("cannot read --flange-truth '" + o.flange_truth + "'");
    std::string line;
    while (std::getline(t, line)) {
      if (line.empty()) continue;
      const nlohmann::json j = nlohmann::json::parse(line);
      true_flange[j.at("stamp_ns").get<int64_t>()] = cellsight_tools::poseFromJson(j.at("T_base_flange"));
    }
  }
  const ScannerSettings settings = loadScannerSettings(o.scanner_config);
  const ScannerCalibration cal = ScannerCalibration::fromFolder(o.calibration);
  ScanCloud cloud;
  cloud.frame_id = "base_link";
  LineExtractionStats stats;
  size_t used = 0;
  for (const auto& fr : frames.at("frames")) {
    const std::string img_path = resolveRelative(o.frames, fr.at("image").get<std::string>());
    const cv::Mat img = readImage(img_path, cv::IMREAD_UNCHANGED);
    Eigen::Isometry3d T = cellsight_tools::poseFromJson(fr.at("T_base_flange"));
    if (!o.flange_truth.empty()) {
      const auto it = true_flange.find(fr.at("stamp_ns").get<int64_t>());
      if (it == true_flange.end())
        throw std::runtime_error(o.flange_truth + ": no true flange pose at the stamp of " + img_path);
      T = it->second;
    }
    cv::Mat grey = img;
    LineExtractionConfig line = settings.line;
    if (img.channels() == 3) {
      cv::cvtColor(img, grey, cv::COLOR_BGR2RGB);  // imread gives BGR; the extraction reads the red channel of RGB
      if (line.channel < 0) line.channel = 0;
    }
    addProfile(grey, T, cal, line, settings.triangulation, cloud, &stats);
    ++used;
  }
  cloud = finishScan(cloud, settings, cal.T_base_camera.translation().cast<float>());  // as the node finishes a scan
  if (!o.ply.empty()) saveCloud(o.ply, cloud);
  nlohmann::json out = {{"frames", used}, {"calibration", o.calibration},
                        {"flange_poses", o.flange_truth.empty() ? "as the robot reported them" : "the simulator's true poses"}};
  if (!o.scene.empty()) {
    const nlohmann::json fig = scanFigures(loadScene(o.scene), cloud, o.sphere_model);
    out.update(fig);
  } else {
    out["points"] = cloud.size();
  }
  std::cout << out.dump(2) << "\n";
  if (!o.json.empty()) writeFileAtomic(o.json, out.dump(2) + "\n");
  return cloud.size() > 0 ? 0 : 1;
}

/// A calibration folder against the scene's truth (the cell as built), and the robot's own
/// positioning error along a trajectory: the calibration and robot rows of the error budget.
int runCalibration(const Options& o) {
  const Scene scene = loadScene(o.scene);
  const ScannerCalibration cal = ScannerCalibration::fromFolder(o.calibration);
  const ScannerCalibration truth = scannerCalibrationOf(scene);
  constexpr double kDeg = M_PI / 180;
  auto angle = [](const Eigen::Matrix3d& a, const Eigen::Matrix3d& b) {
    return Eigen::AngleAxisd(a.transpose() * b).angle();
  };
  nlohmann::json out;
  out["calibration"] = o.calibration;
  out["intrinsics"] = {{"fx_error_px", cal.intrinsics.fx - truth.intrinsics.fx},
                       {"fy_error_px", cal.intrinsics.fy - truth.intrinsics.fy},
                       {"cx_error_px", cal.intrinsics.cx - truth.intrinsics.cx},
                       {"cy_error_px", cal.intrinsics.cy - truth.intrinsics.cy}};
  // where the intrinsics put the workspace's points: pixel error of the calibrated model against
  // the true one for a grid of workspace points (camera pose from the truth)
  double px_max = 0, px_sum2 = 0;
  int n = 0;
  const Eigen::Isometry3d T_cam_base = truth.T_base_camera.inverse();
  for (int i = 0; i <= 8; ++i)
    for (int j = 0; j <= 8; ++j) {
      const Eigen::Vector3d p = scene.workspace.min() +
                                Eigen::Vector3d(i / 8.0, j / 8.0, 0.5).cwiseProduct(scene.workspace.sizes());
      const double d = (cal.intrinsics.project(T_cam_base * p) - truth.intrinsics.project(T_cam_base * p)).norm();
      px_max = std::max(px_max, d);
      px_sum2 += d * d;
      ++n;
    }
  out["intrinsics"]["workspace_reprojection_rms_px"] = std::sqrt(px_sum2 / n);
  out["intrinsics"]["workspace_reprojection_max_px"] = px_max;
  out["camera_pose"] = {
      {"position_error_mm", (cal.T_base_camera.translation() - truth.T_base_camera.translation()).norm() * 1e3},
      {"rotation_error_deg", angle(cal.T_base_camera.linear(), truth.T_base_camera.linear()) / kDeg}};
  // the light sheet in the flange frame: angle between the planes, and their distance along the
  // true sheet's normal at a point 0.25 m down its central beam (the working distance)
  const Plane est = laserPlane(cal.T_flange_laser), tru = laserPlane(truth.T_flange_laser);
  const Eigen::Vector3d probe = truth.T_flange_laser * Eigen::Vector3d(0, 0, 0.25);
  out["light_sheet"] = {{"angle_error_deg", std::acos(std::min(1.0, std::abs(est.n.dot(tru.n)))) / kDeg},
                        {"offset_at_0.25m_mm", std::abs(est.distance(probe)) * 1e3}};
  // the robot: where the flange really goes against where it is told, along the trajectory
  const RobotErrorModel robot(scene.as_built.robot);
  std::vector<double> err;
  double rot_max = 0;
  if (!o.trajectories.empty() && robot.enabled()) {
    const Trajectory t = loadTrajectories(o.trajectories).at(o.trajectory);
    for (const auto& P : t.poses) {
      const Eigen::Isometry3d A = robot.actualSystematic(P);
      err.push_back((A.translation() - P.translation()).norm() * 1e3);
      rot_max = std::max(rot_max, angle(A.linear(), P.linear()) / kDeg);
    }
  }
  if (!err.empty()) {
    double s2 = 0;
    for (double e : err) s2 += e * e;
    out["robot"] = {{"trajectory", o.trajectory},
                    {"absolute_position_error_rms_mm", std::sqrt(s2 / err.size())},
                    {"absolute_position_error_max_mm", *std::max_element(err.begin(), err.end())},
                    {"absolute_position_error_range_mm",
                     *std::max_element(err.begin(), err.end()) - *std::min_element(err.begin(), err.end())},
                    {"orientation_error_max_deg", rot_max},
                    {"repeatability_sigma_mm", scene.as_built.robot.repeatability_mm}};
  } else {
    out["robot"] = {{"exact", true}};
  }
  std::cout << out.dump(2) << "\n";
  if (!o.json.empty()) writeFileAtomic(o.json, out.dump(2) + "\n");
  return 0;
}

// Two clouds of the same scan (live and replayed): same points? Sorted lexicographically and
// compared point by point; exit 0 when the counts match and every distance ≤ --tolerance-m.
int runCompare(const Options& o) {
  ScanCloud x = loadCloud(o.a), y = loadCloud(o.b);
  const double tol = o.tolerance_m;
  auto sorted = [](const ScanCloud& c) {
    std::vector<Eigen::Vector3f> p = c.points;
    std::sort(p.begin(), p.end(), [](const Eigen::Vector3f& l, const Eigen::Vector3f& r) {
      return std::tie(l.x(), l.y(), l.z()) < std::tie(r.x(), r.y(), r.z());
    });
    return p;
  };
  const auto px = sorted(x), py = sorted(y);
  double max_d = 0;
  const bool same_count = px.size() == py.size();
  if (same_count) {
    for (size_t i = 0; i < px.size(); ++i) max_d = std::max(max_d, static_cast<double>((px[i] - py[i]).norm()));
  }
  nlohmann::json out = {{"points_a", px.size()}, {"points_b", py.size()}, {"max_distance_m", same_count ? max_d : -1.0},
                        {"tolerance_m", tol}, {"same", same_count && max_d <= tol}};
  std::cout << out.dump(2) << "\n";
  return same_count && max_d <= tol ? 0 : 1;
}

int runCloud(const Options& o) {
  const ScanCloud c = loadCloud(o.cloud);
  const std::vector<double>& ctr = o.center;
  if (ctr.size() != 3) throw std::invalid_argument("--center x,y,z (metres) is required");
  const double r = o.radius_mm * 1e-3;
  const SphereFit f = fitSphere(near(c, {ctr[0], ctr[1], ctr[2]}, r + o.margin_mm * 1e-3));
  nlohmann::json out = sphereJson(f);
  std::cout << out.dump(2) << "\n";
  if (!o.json.empty()) writeFileAtomic(o.json, out.dump(2) + "\n");
  return f.ok ? 0 : 1;
}

/// --scene, --sphere-model, --k and --json (sim and scan).
CLI::Option* addCommon(CLI::App* c, Options& o, const std::string& k_help) {
  c->add_option("--scene", o.scene, "scene YAML")->required()->check(CLI::ExistingFile);
  c->add_option("--sphere-model", o.sphere_model, "model id of the reference sphere in the scene")->capture_default_str();
  CLI::Option* k = c->add_option("--k", o.k, k_help)->check(cellsight_tools::positiveInt());
  c->add_option("--json", o.json, "also write the JSON to this file");
  return k;
}

}  // namespace

int main(int argc, char** argv) {
  using cellsight_tools::nonNegative;
  using cellsight_tools::positive;
  CLI::App app("Scanner acceptance figures (thesis section 1, after CMM tests): surface error, MPE_P, MPE_AL, "
               "flatness; JSON on stdout.",
               "cellsight_scanner_accuracy");
  app.require_subcommand(1);

  Options sim;
  CLI::App* c_sim = app.add_subcommand(
      "sim", "scan the simulated scene in-process (the scanner's own extraction and triangulation): surface error "
             "vs truth, MPE_P and MPE_AL on the reference sphere, flatness of a bare table patch");
  addCommon(c_sim, sim, "sphere scans, the projector turned 360/K apart")->capture_default_str();
  c_sim->add_option("--trajectories", sim.trajectories, "trajectories YAML (needed unless --trajectory none)")
      ->check(CLI::ExistingFile);
  c_sim->add_option("--trajectory", sim.trajectory, "trajectory of the whole-scene scan; none: skip that scan")
      ->capture_default_str();
  c_sim->add_flag("--no-noise", sim.no_noise, "render without the noise model");
  c_sim->add_option("--settings", sim.line_settings,
                    "scanner settings YAML whose line: section to use, as the triangulation node (e.g. config/scanner.yaml)")
      ->check(CLI::ExistingFile);
  c_sim->add_option("--estimator", sim.estimator, "line-centre estimator (overrides the settings')")
      ->check(cellsight_tools::parsedBy([](const std::string& e) { LineExtractionConfig::parseEstimator(e); },
                                        "{ridge,centroid,gaussian3,run_centre}"))
      ->capture_default_str();
  c_sim->add_option("--centroid-floor", sim.line.centroid_floor, "centroid weight floor, share of peak - background")
      ->check(cellsight_tools::fraction())
      ->capture_default_str();
  c_sim->add_option("--background-percentile", sim.line.background_percentile, "background grey level: this histogram quantile")
      ->check(cellsight_tools::fraction())
      ->capture_default_str();
  c_sim->add_option("--smoothing-degree", sim.line.smoothing_degree, "degree of the centre-line smoothing; 0: off")
      ->check(cellsight_tools::nonNegativeInt())
      ->capture_default_str();
  c_sim->add_option("--sphere-step-mm", sim.sphere_step_mm, "flange step of the sphere sweeps [mm]")
      ->check(positive())
      ->capture_default_str();
  c_sim->add_flag("--no-filter", sim.no_filter, "no statistical outlier removal");
  c_sim->add_option("--ply", sim.ply, "save the whole-scene scan to this cloud file");

  Options scan;
  CLI::App* c_scan = app.add_subcommand(
      "scan", "a scan made elsewhere (the ROS demo) against the scene's truth; with --k also the in-process "
              "K-orientation sphere scans for MPE_AL");
  CLI::Option* scan_k = addCommon(c_scan, scan, "also K in-process sphere scans for MPE_AL (none without --k)");
  c_scan->add_option("--cloud", scan.cloud, "the scan (PLY, PCD)")->required()->check(CLI::ExistingFile);

  c_scan->add_option("--calibration", scan.calibration,
                     "calibration folder the K sphere sweeps use (default: the simulator's truth)")
      ->check(CLI::ExistingDirectory);

  Options frm;
  CLI::App* c_frm = app.add_subcommand(
      "frames", "a recorded scan (frames.json + PNGs) triangulated again in-process with a given calibration (and "
                "optionally the true flange poses): the cloud, and its figures against --scene");
  c_frm->add_option("--frames", frm.frames, "frames.json written by camera_trigger (~save_dir)")->required()->check(CLI::ExistingFile);
  c_frm->add_option("--calibration", frm.calibration, "calibration folder (camera_info + transform YAMLs)")
      ->required()
      ->check(CLI::ExistingDirectory);
  c_frm->add_option("--flange-truth", frm.flange_truth, "frames_truth.jsonl of the simulator: use its true flange poses");
  c_frm->add_option("--scanner-config", frm.scanner_config, "line extraction, crop and filter settings")
      ->check(CLI::ExistingFile)
      ->capture_default_str();
  c_frm->add_option("--scene", frm.scene, "scene YAML: also the figures against its truth")->check(CLI::ExistingFile);
  c_frm->add_option("--sphere-model", frm.sphere_model, "reference sphere model id")->capture_default_str();
  c_frm->add_option("--ply", frm.ply, "write the cloud here");
  c_frm->add_option("--json", frm.json, "also write the JSON to this file");

  Options cal;
  CLI::App* c_cal = app.add_subcommand(
      "calibration", "a calibration folder against the scene's truth (intrinsics, camera pose, light sheet) and the "
                     "simulated robot's absolute error along a trajectory");
  c_cal->add_option("--calibration", cal.calibration, "calibration folder")->required()->check(CLI::ExistingDirectory);
  c_cal->add_option("--scene", cal.scene, "scene YAML (its as_built cell is the truth)")->required()->check(CLI::ExistingFile);
  c_cal->add_option("--trajectories", cal.trajectories, "trajectories YAML: the robot's error along --trajectory")
      ->check(CLI::ExistingFile);
  c_cal->add_option("--trajectory", cal.trajectory, "trajectory name")->capture_default_str();
  c_cal->add_option("--json", cal.json, "also write the JSON to this file");

  Options cmp;
  CLI::App* c_cmp = app.add_subcommand(
      "compare", "two clouds of the same scan (live, replayed): exit 0 when the counts match and every sorted point "
                 "is within --tolerance-m");
  c_cmp->add_option("--a", cmp.a, "first cloud (PLY, PCD)")->required()->check(CLI::ExistingFile);
  c_cmp->add_option("--b", cmp.b, "second cloud (PLY, PCD)")->required()->check(CLI::ExistingFile);
  c_cmp->add_option("--tolerance-m", cmp.tolerance_m, "largest distance between paired points [m]")
      ->check(nonNegative())
      ->capture_default_str();

  Options cld;
  CLI::App* c_cld = app.add_subcommand("cloud", "MPE_P / sphere fit on any cloud near a given centre (real data)");
  c_cld->add_option("--cloud", cld.cloud, "the cloud (PLY, PCD)")->required()->check(CLI::ExistingFile);
  c_cld->add_option("--center", cld.center, "sphere centre x,y,z [m]")->required()->delimiter(',')->expected(3);
  c_cld->add_option("--radius-mm", cld.radius_mm, "sphere radius [mm]")->check(positive())->capture_default_str();
  c_cld->add_option("--margin-mm", cld.margin_mm, "points within radius + margin of the centre are fitted [mm]")
      ->check(nonNegative())
      ->capture_default_str();
  c_cld->add_option("--json", cld.json, "also write the JSON to this file");

  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  scan.k_given = scan_k->count() > 0;
  return cellsight_tools::runTool([&] {
    sim.estimator_given = c_sim->count("--estimator") > 0;
    if (c_sim->parsed()) return runSim(sim);
    if (c_scan->parsed()) return runScan(scan);
    if (c_frm->parsed()) return runFrames(frm);
    if (c_cal->parsed()) return runCalibration(cal);
    if (c_cmp->parsed()) return runCompare(cmp);
    return runCloud(cld);
  });
}
