// Scanner acceptance figures (thesis §1, after CMM tests):
//   sim:   scans the simulated scene in-process with the scanner's own extraction and
//          triangulation; reports the distance of scan points to the true surfaces, MPE_P on the
//          reference sphere (one motion), MPE_AL (K sphere scans with different projector
//          orientations; diameter of the smallest sphere holding the K fitted centres) and the
//          flatness of a bare table patch.
//   cloud: MPE_P / sphere fit on any PLY/PCD cloud near a given centre (real data).
// Output: JSON on stdout and, with --json FILE, written atomically.
#include <cmath>
#include <cstring>
#include <iostream>
#include <map>
#include <nlohmann/json.hpp>
#include <numeric>
#include <sstream>
#include <tuple>

#include "cli_args.hpp"
#include "cellsight/accuracy.hpp"
#include "cellsight/evaluation.hpp"
#include "cellsight/file_io.hpp"
#include "cellsight/sim_scan.hpp"
#include "cellsight/trajectory.hpp"

using namespace cellsight;

namespace {

using cellsight_tools::Args;
using cellsight_tools::parse;

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

int runSim(const Args& a) {
  Scene scene = loadScene(a.get("scene"));
  if (a.flag("no-noise")) scene.noise.enabled = false;
  LineExtractionConfig line;
  line.estimator = LineExtractionConfig::parseEstimator(a.get("estimator", "centroid"));
  line.centroid_floor = std::stod(a.get("centroid-floor", std::to_string(line.centroid_floor)));
  line.background_percentile = std::stod(a.get("background-percentile", std::to_string(line.background_percentile)));
  line.smoothing_degree = std::stoi(a.get("smoothing-degree", std::to_string(line.smoothing_degree)));
  TriangulationConfig tri;
  auto geometry = std::make_shared<CellGeometry>(scene);
  ScannerRenderer renderer(geometry);
  const ScannerCalibration cal = ScannerCalibration::fromScene(scene);
  const Eigen::AlignedBox3f ws(scene.workspace.min().cast<float>() - Eigen::Vector3f::Constant(0.002f),
                               scene.workspace.max().cast<float>() + Eigen::Vector3f::Constant(0.002f));
  nlohmann::json out;
  out["scene"] = scene.file;
  out["noise"] = scene.noise.enabled;
  out["estimator"] = a.get("estimator", "centroid");

  // 1. The whole scene along a named trajectory: surface error vs truth.
  const std::string traj_name = a.get("trajectory", "demo_sweep");
  if (traj_name != "none") {
    const Trajectory traj = loadTrajectories(a.get("trajectories")).at(traj_name);
    SimScanStats st;
    ScanCloud raw = simulateScan(renderer, traj.poses, cal, line, tri, scene.noise.seed, &st);
    ScanCloud cloud = cropBox(raw, ws);
    if (!a.flag("no-filter")) cloud = statisticalOutlierRemoval(cloud, 20, 3.0);
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
    if (a.kv.count("ply")) saveCloud(a.get("ply"), cloud);
  }

  // 2. Reference sphere: K scans with the projector turned by 360°/K each.
  const SceneObject* sphere = nullptr;
  for (const auto& o : scene.objects) {
    if (o.model == a.get("sphere-model", "sphere25")) sphere = &o;
  }
  if (sphere) {
    const int K = std::stoi(a.get("k", "5"));
    const double step = std::stod(a.get("sphere-step-mm", "0.5")) * 1e-3;
    const SphereAcceptance acc = sphereAcceptance(renderer, *sphere, cal, line, tri, K, step, !a.flag("no-filter"));
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
        for (const auto& o : scene.objects) {
          Eigen::AlignedBox3d b;
          const TriangleMesh m = loadValidMesh(o.info.mesh_file);
          for (const auto& v : m.vertices) b.extend(o.T_base_object * v.cast<double>());
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
    if (!a.flag("no-filter")) c = statisticalOutlierRemoval(c, 20, 3.0);
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
  if (a.kv.count("json")) writeFileAtomic(a.get("json"), out.dump(2) + "\n");
  return 0;
}

// A scan made elsewhere (the ROS demo) against the scene's truth, plus, with --k, the
// in-process K-orientation sphere scans for MPE_AL.
int runScan(const Args& a) {
  const Scene scene = loadScene(a.get("scene"));
  const ScanCloud cloud = loadCloud(a.get("cloud"));
  std::vector<Eigen::Vector3d> pts = toDouble(cloud);
  const SurfaceErrorStats e = SurfaceDistance(scene).stats(pts);
  nlohmann::json out;
  out["points"] = cloud.size();
  out["surface_error_rms_mm"] = e.rms * 1e3;
  out["surface_error_max_mm"] = e.max * 1e3;
  out["surface_error_p99_mm"] = e.p99 * 1e3;
  out["surface_error_mean_mm"] = e.mean_abs * 1e3;
  for (const auto& o : scene.objects) {
    if (o.model != a.get("sphere-model", "sphere25")) continue;
    const TriangleMesh mesh = loadValidMesh(o.info.mesh_file);
    const Eigen::Vector3d center = o.T_base_object * mesh.bounds().center().cast<double>();
    const double radius = 0.5 * mesh.bounds().sizes().x();
    std::vector<Eigen::Vector3d> sp;
    for (const auto& p : near(cloud, center, radius + 0.003)) {
      if (p.z() > scene.table.z + 0.002) sp.push_back(p);
    }
    const SphereFit f = fitSphere(sp);
    out["sphere_in_scan"] = sphereJson(f);
    out["mpe_p_mm"] = f.max_abs_dev * 1e3;
  }
  if (a.kv.count("k")) {
    Scene s = scene;
    LineExtractionConfig line;
    ScannerRenderer renderer(std::make_shared<CellGeometry>(s));
    for (const auto& o : s.objects) {
      if (o.model != a.get("sphere-model", "sphere25")) continue;
      const SphereAcceptance acc = sphereAcceptance(renderer, o, ScannerCalibration::fromScene(s), line, {},
                                                    std::stoi(a.get("k")), 0.5e-3, true);
      out["mpe_al_mm"] = acc.mpe_al * 1e3;
      out["mpe_p_dedicated_sweep_mm"] = acc.mpe_p * 1e3;
      out["mpe_al_k"] = std::stoi(a.get("k"));
      out["mpe_al_method"] = "K in-process sphere sweeps (same extraction and triangulation as the nodes), projector turned 360/K apart";
    }
  }
  std::cout << out.dump(2) << "\n";
  if (a.kv.count("json")) writeFileAtomic(a.get("json"), out.dump(2) + "\n");
  return 0;
}

// Two clouds of the same scan (live and replayed): same points? Sorted lexicographically and
// compared point by point; exit 0 when the counts match and every distance ≤ --tolerance-m.
int runCompare(const Args& a) {
  ScanCloud x = loadCloud(a.get("a")), y = loadCloud(a.get("b"));
  const double tol = std::stod(a.get("tolerance-m", "1e-6"));
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

int runCloud(const Args& a) {
  const ScanCloud c = loadCloud(a.get("cloud"));
  std::vector<double> ctr;
  std::stringstream ss(a.get("center"));
  for (std::string tok; std::getline(ss, tok, ',');) ctr.push_back(std::stod(tok));
  if (ctr.size() != 3) throw std::invalid_argument("--center x,y,z (metres) is required");
  const double r = std::stod(a.get("radius-mm", "12.5")) * 1e-3;
  const SphereFit f = fitSphere(near(c, {ctr[0], ctr[1], ctr[2]}, r + std::stod(a.get("margin-mm", "3")) * 1e-3));
  nlohmann::json out = sphereJson(f);
  std::cout << out.dump(2) << "\n";
  if (a.kv.count("json")) writeFileAtomic(a.get("json"), out.dump(2) + "\n");
  return f.ok ? 0 : 1;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string usage =
      "usage: cellsight_scanner_accuracy sim --scene S.yaml --trajectories T.yaml [--trajectory demo_sweep|none]\n"
      "         [--no-noise] [--estimator centroid|gaussian3|run_centre] [--smoothing-degree N]\n"
      "         [--k 5] [--sphere-step-mm 0.5] [--no-filter] [--ply scan.ply] [--json out.json]\n"
      "       cellsight_scanner_accuracy scan --scene S.yaml --cloud scan.ply [--k 5] [--json out.json]\n"
      "       cellsight_scanner_accuracy compare --a live.ply --b replay.ply [--tolerance-m 1e-6]\n"
      "       cellsight_scanner_accuracy cloud --cloud scan.ply --center x,y,z [--radius-mm 12.5] [--json out.json]\n";
  if (argc < 2) {
    std::cerr << usage;
    return 2;
  }
  try {
    const std::string mode = argv[1];
    const Args a = parse(argc, argv, 2);
    if (mode == "sim") return runSim(a);
    if (mode == "cloud") return runCloud(a);
    if (mode == "scan") return runScan(a);
    if (mode == "compare") return runCompare(a);
    std::cerr << usage;
    return 2;
  } catch (const std::exception& e) {
    std::cerr << "error: " << e.what() << "\n";
    return 1;
  }
}
