#include "cellsight/eval/planning_eval.hpp"

#include <chrono>
#include <cmath>

#include "cellsight/common/file_io.hpp"
#include "cellsight/common/trajectory.hpp"
#include "cellsight/eval/sim_scan.hpp"
#include "cellsight/localization/clustering.hpp"
#include "cellsight/localization/model_library.hpp"
#include "cellsight/localization/instance_names.hpp"
#include "cellsight/localization/model_matching.hpp"
#include "cellsight/localization/scan_localization.hpp"
#include "cellsight/scanner/scan_pipeline.hpp"
#include "cellsight/scanner/scanner_config.hpp"
#include "cellsight/sim/renderer.hpp"
#include "cellsight/sim/scene.hpp"

namespace cellsight {

namespace {

double now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

std::string under(const std::string& root, const std::string& p) {
  return !p.empty() && p[0] == '/' ? p : root + "/" + p;
}

}  // namespace

void placementDeviation(const ModelInfo& info, const Eigen::Vector3d& centroid, const Eigen::Isometry3d& placed,
                        const Eigen::Isometry3d& target, Eigen::Vector3d* offset, Eigen::Vector3d* rotation) {
  *offset = placed * centroid - target * centroid;
  Eigen::Vector3d best = Eigen::Vector3d::Zero();
  double best_angle = 1e9;
  for (const auto& S : symmetryRotations(info, 360)) {
    const Eigen::AngleAxisd aa(placed.linear() * (target.linear() * S.linear()).transpose());
    if (aa.angle() < best_angle) {
      best_angle = aa.angle();
      best = aa.axis() * aa.angle();
    }
  }
  if (info.symmetry.type == Symmetry::Type::kAxial) {
    const Eigen::Vector3d axis = (placed.linear() * info.symmetry.axis).normalized();
    best -= axis * axis.dot(best);
  } else if (info.symmetry.type == Symmetry::Type::kSpherical) {
    best.setZero();
  }
  *rotation = best;
}

Eigen::Isometry3d simulatePlacement(const ArmModel& arm, const RobotErrorModel& robot, const PartPlan& plan,
                                    const Eigen::Isometry3d& T_base_part_true, uint64_t move) {
  // the controller holds the plan's joints; the arm as built puts the flange where they lead
  const Eigen::Isometry3d tcp_grasp = robot.actualAtJoints(plan.trajectory.positions.at(plan.grasp_index), move) * arm.toolTcp();
  const Eigen::Isometry3d tcp_release =
      robot.actualAtJoints(plan.trajectory.positions.at(plan.release_index), move + 1) * arm.toolTcp();
  return tcp_release * (tcp_grasp.inverse() * T_base_part_true);
}

struct PlanningEvaluation::Impl {
  PlanningEvalConfig config;
  Scene scene;
  std::shared_ptr<const ModelLibrary> lib;
  std::unique_ptr<ModelMatcher> matcher;
  ClusteringConfig clustering;
  ScannerSettings settings;
  Trajectory sweep, refine_sweep;
  ScannerCalibration cal;
  std::unique_ptr<ScannerRenderer> renderer;
  std::unique_ptr<RobotErrorModel> robot, executor;
  std::unique_ptr<ArmModel> arm;
  AssemblyConfig assembly;
  std::map<std::string, std::pair<ModelInfo, std::shared_ptr<const TriangleMesh>>> models;
  std::unique_ptr<GraspPlanner> planner;
};

PlanningEvaluation::PlanningEvaluation(const PlanningEvalConfig& config) : impl_(std::make_unique<Impl>()) {
  Impl& m = *impl_;
  m.config = config;
  const std::string& root = config.root;
  m.scene = loadScene(under(root, config.scene));
  m.lib = std::make_shared<const ModelLibrary>(root + "/config/models");
  m.matcher = std::make_unique<ModelMatcher>(m.lib, loadMatchingConfig(root + "/config/matching.yaml"));
  m.matcher->prepare({});
  m.clustering = loadClusteringConfig(root + "/config/clustering.yaml");
  m.settings = loadScannerSettings(root + "/config/scanner.yaml");
  m.sweep = loadTrajectory(root + "/config/trajectories.yaml", config.trajectory);
  if (!config.refine_trajectory.empty())
    m.refine_sweep = loadTrajectory(root + "/config/trajectories.yaml", config.refine_trajectory);
  m.cal = config.calibration.empty() ? scannerCalibrationOf(m.scene) : ScannerCalibration::fromFolder(config.calibration);
  m.renderer = std::make_unique<ScannerRenderer>(std::make_shared<CellGeometry>(m.scene));
  m.robot = std::make_unique<RobotErrorModel>(m.scene.as_built.robot);
  m.executor = std::make_unique<RobotErrorModel>(config.exact_robot ? RobotErrorConfig{} : m.scene.as_built.robot);
  m.arm = std::make_unique<ArmModel>(ArmModel::fromUrdfFile(root + "/urdf/cellsight_arm.urdf"));
  m.assembly = loadAssemblyConfig(root + "/config/assembly.yaml");
  for (const std::string& id : m.lib->ids()) {
    const ModelEntry& e = m.lib->model(id);
    if (e.mesh.faces.empty()) continue;
    m.models[id] = {e.info, std::make_shared<TriangleMesh>(e.mesh)};
  }
  m.planner = std::make_unique<GraspPlanner>(*m.arm, m.assembly, config.gripper, config.motion, m.models);
}

PlanningEvaluation::~PlanningEvaluation() = default;

CycleReport PlanningEvaluation::run(uint64_t seed) {
  Impl& m = *impl_;
  CycleReport rep;
  rep.seed = seed;
  // scan as the cell does: the robot as built moves, the scanner triangulates with `cal`
  double t0 = now();
  const Eigen::Vector3f eye = m.cal.T_base_camera.translation().cast<float>();
  auto scan = [&](const Trajectory& t, uint64_t noise_seed) {
    return finishScan(simulateScan(*m.renderer, t.poses, m.cal, m.settings.line, m.settings.triangulation, noise_seed,
                                   nullptr, m.robot.get()),
                      m.settings, eye);
  };
  // the sheet frame by frame as the scanner knows it (reported flange poses, calibrated laser)
  auto light = [&](const Trajectory& t) {
    return LightSweep::fromFlangePoses(t.poses, m.cal.T_flange_laser, m.settings.laser_fan_angle / 2);
  };
  ScanCloud cloud = scan(m.sweep, seed);
  rep.scan_seconds = now() - t0;
  if (!m.config.dump_scans.empty()) saveCloud(m.config.dump_scans + "/scan_" + std::to_string(seed) + ".ply", cloud);
  rep.scan_points = cloud.size();
  t0 = now();
  std::vector<ScanPass> passes{scanPass(PassRole::kDetect, clusterScene(cloud, m.clustering), eye, light(m.sweep))};
  rep.locate_seconds = now() - t0;  // clustering; the matcher's time is added below
  if (!m.refine_sweep.poses.empty()) {
    // the second pass: its own image noise (another seed space), its own robot moves
    t0 = now();
    const ScanCloud second = scan(m.refine_sweep, seed + 1000003);
    rep.refine_scan_seconds = now() - t0;
    t0 = now();
    passes.push_back(scanPass(PassRole::kRefine, clusterScene(second, m.clustering), eye, light(m.refine_sweep)));
    rep.refine_seconds = now() - t0;
  }
  const LocatedScan located = locateScan(*m.matcher, passes);
  const std::vector<PartDetection>& found = located.parts;
  rep.locate_seconds += located.passes.front().stats.seconds;
  if (passes.size() > 1) {
    rep.refine_seconds += located.passes.back().stats.seconds;
    for (const auto& d : found) rep.refined += d.refined ? 1 : 0;
    rep.refine_warnings = located.passes.back().stats.warnings;
  }
  // named as the model_matching node names them (the first scan: no earlier instances)
  std::vector<NamedInstance> current;
  for (const auto& d : found) current.push_back({d.model, "", d.pose.translation()});
  const std::vector<std::string> names = assignInstanceNames({}, current, 0.05, "");
  std::vector<LocatedPart> parts;
  for (size_t i = 0; i < found.size(); ++i) parts.push_back({names[i], found[i].model, found[i].pose, found[i].ambiguous_poses});
  if (m.config.true_poses) {
    parts.clear();
    for (const SceneObject& o : m.scene.objects) parts.push_back({o.name, o.model, o.T_base_object, {}});
  }
  // the truth each detection stands for: the nearest true object of its model (scoring only)
  std::vector<int> truth(parts.size(), -1);
  for (size_t i = 0; i < parts.size(); ++i) {
    double best = 0.02;
    for (size_t k = 0; k < m.scene.objects.size(); ++k) {
      const SceneObject& o = m.scene.objects[k];
      if (o.model != parts[i].model) continue;
      const double d = (o.T_base_object.translation() - parts[i].pose.translation()).norm();
      if (d < best) {
        best = d;
        truth[i] = static_cast<int>(k);
      }
    }
  }
  for (size_t i = 0; i < parts.size(); ++i) {
    if (truth[i] < 0 || !m.models.count(parts[i].model)) continue;
    const SceneObject& o = m.scene.objects[static_cast<size_t>(truth[i])];
    const PoseError e = poseError(o.info, m.models.at(o.model).second->surfaceCentroid(), parts[i].pose, o.T_base_object);
    Eigen::Vector3d off, rot;
    placementDeviation(o.info, m.models.at(o.model).second->surfaceCentroid(), parts[i].pose, o.T_base_object, &off, &rot);
    rep.locate_errors[parts[i].name] = {parts[i].model, e.translation * 1e3, e.rotation * 180 / M_PI, off * 1e3, rot * 180 / M_PI};
  }
  t0 = now();
  CollisionWorld world(CollisionWorldConfig{}, m.scene.table.z, m.scene.table.center, m.scene.table.size);
  m.planner->setScene(world, parts, cloud.points);
  rep.world_seconds = now() - t0;
  rep.voxels = m.planner->world().occupiedVoxels();
  // the assembly, part after part, from home
  JointVector q = m.assembly.home;
  std::map<int, Eigen::Isometry3d> true_pose;  // truth as the parts move
  for (size_t k = 0; k < m.scene.objects.size(); ++k) true_pose[static_cast<int>(k)] = m.scene.objects[k].T_base_object;
  int base_truth = -1;
  for (size_t k = 0; k < m.scene.objects.size(); ++k) {
    if (m.scene.objects[k].model == m.assembly.base_model) base_truth = static_cast<int>(k);
  }
  uint64_t move = seed * 1000;
  for (size_t round = 0; round < parts.size(); ++round) {
    size_t idx = parts.size();
    const PartPlan plan = m.planner->planNext(q, &idx);
    rep.plan_seconds += plan.seconds;
    if (idx >= parts.size() || plan.status == PlanStatus::kNothingLeft) break;
    PlacementResult pr;
    pr.name = parts[idx].name;
    pr.model = parts[idx].model;
    pr.status = planStatusName(plan.status);
    pr.reason = plan.reason;
    pr.plan_seconds = plan.seconds;
    pr.sampled = plan.sampled;
    pr.candidates_tried = plan.candidates_tried;
    if (plan.status != PlanStatus::kOk) {
      rep.placements.push_back(pr);
      // the part stays; the others go on
      m.planner->skip(idx);
      continue;
    }
    pr.motion_seconds = plan.trajectory.duration();
    if (truth[idx] >= 0) {
      const int t = truth[idx];
      pr.truth = m.scene.objects[static_cast<size_t>(t)].name;
      const Eigen::Isometry3d placed = simulatePlacement(*m.arm, *m.executor, plan, true_pose[t], move);
      true_pose[t] = placed;
      pr.executed = true;
      if (base_truth >= 0) {
        const ModelInfo& info = m.scene.objects[static_cast<size_t>(t)].info;
        const Eigen::Isometry3d target = m.scene.objects[static_cast<size_t>(base_truth)].T_base_object * info.T_0i;
        const auto& mesh = m.models.at(pr.model).second;
        const PoseError e = poseError(info, mesh->surfaceCentroid(), placed, target);
        pr.place_t_err_mm = e.translation * 1e3;
        pr.place_r_err_deg = e.rotation * 180 / M_PI;
        Eigen::Vector3d off, rot;
        placementDeviation(info, mesh->surfaceCentroid(), placed, target, &off, &rot);
        pr.offset_mm = off * 1e3;
        pr.rotation_deg = rot * 180 / M_PI;
      }
    } else {
      pr.status = "no_part";
      pr.reason = "the detection matches no part of the scene: the jaws closed on nothing";
    }
    move += 2;
    m.planner->commit(idx, plan);
    q = plan.poses.back().q;
    rep.placements.push_back(pr);
  }
  return rep;
}

}  // namespace cellsight
