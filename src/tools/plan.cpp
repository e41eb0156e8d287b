// cellsight_plan: grasp and assembly planning figures (docs/planning.md).
// Usage: cellsight_plan SUBCOMMAND [OPTIONS]   (--help on the tool and each subcommand)
//   cycles   full cell cycles in-process (scan, locate, plan, execute with the robot as built):
//            placement error against the simulator's truth, planning times; exit 3 when a limit fails
//   reach    reachability of the table area for the gripper pointing down (and tilted)
//   demo     the demo's assembly (assembly_client's steps, cell_sim's truth) against the targets
// Failures print "error: ..." and exit 1; bad options are reported by CLI11.
#include <algorithm>
#include <cmath>
#include <cstdio>
#include <nlohmann/json.hpp>
#include <numeric>

#include "cellsight/common/file_io.hpp"
#include "cellsight/localization/model_matching.hpp"
#include <fstream>
#include "cellsight/eval/planning_eval.hpp"
#include "cellsight/sim/scene.hpp"
#include "cli_args.hpp"
#include "json_pose.hpp"

using namespace cellsight;
using json = nlohmann::json;

namespace {

using cellsight_tools::median;
using cellsight_tools::writeJson;

double stddev(const std::vector<double>& v) {
  if (v.size() < 2) return 0;
  const double m = std::accumulate(v.begin(), v.end(), 0.0) / static_cast<double>(v.size());
  double s = 0;
  for (double x : v) s += (x - m) * (x - m);
  return std::sqrt(s / static_cast<double>(v.size() - 1));
}

struct CyclesOptions {
  std::string root = ".", scene = "config/scenes/demo.yaml", calibration, json_path;
  int cycles = 20;
  long first_seed = 1;
  double limit_sigma_mm = 0, limit_sigma_deg = 0, limit_median_plan_ms = 0, limit_success = 0, limit_max_mm = 0;
  bool exact_robot = false, true_poses = false;
  std::string trajectory = "demo_sweep", refine_trajectory = "cross_sweep", dump_scans;
};

int runCycles(const CyclesOptions& o) {
  PlanningEvalConfig cfg;
  cfg.root = o.root;
  cfg.scene = o.scene;
  cfg.calibration = o.calibration;
  cfg.exact_robot = o.exact_robot;
  cfg.trajectory = o.trajectory;
  cfg.refine_trajectory = o.refine_trajectory == "none" ? "" : o.refine_trajectory;
  cfg.true_poses = o.true_poses;
  cfg.dump_scans = o.dump_scans;
  PlanningEvaluation ev(cfg);
  json out = {{"scene", o.scene},
              {"exact_robot", o.exact_robot},
              {"trajectory", o.trajectory},
              {"refine_trajectory", cfg.refine_trajectory},
              {"true_poses", o.true_poses},
              {"calibration", o.calibration.empty() ? "the simulator's true calibration (not the system's figure)" : o.calibration},
              {"cycles", json::array()}};
  std::map<std::string, std::vector<Eigen::Vector3d>> offsets, rotations, loc_offsets, loc_rotations;
  std::map<std::string, std::vector<double>> terr, rerr;
  std::vector<double> plan_ms;
  int attempted = 0, placed = 0;
  for (int c = 0; c < o.cycles; ++c) {
    const uint64_t seed = static_cast<uint64_t>(o.first_seed + c);
    const CycleReport r = ev.run(seed);
    json cj = {{"seed", seed},           {"scan_points", r.scan_points},     {"located", r.located},
               {"voxels", r.voxels},     {"scan_seconds", r.scan_seconds},   {"locate_seconds", r.locate_seconds},
               {"world_seconds", r.world_seconds}, {"plan_seconds", r.plan_seconds}, {"placements", json::array()},
               {"refine_scan_seconds", r.refine_scan_seconds}, {"refine_seconds", r.refine_seconds},
               {"refined", r.refined}, {"refine_warnings", r.refine_warnings}};
    cj["locate_errors"] = json::object();
    for (const auto& [name, e] : r.locate_errors) {
      cj["locate_errors"][name] = {{"t_err_mm", e.t_err_mm},
                                   {"r_err_deg", e.r_err_deg},
                                   {"offset_mm", {e.offset_mm.x(), e.offset_mm.y(), e.offset_mm.z()}},
                                   {"rotation_deg", {e.rotation_deg.x(), e.rotation_deg.y(), e.rotation_deg.z()}}};
      loc_offsets[e.model].push_back(e.offset_mm);
      loc_rotations[e.model].push_back(e.rotation_deg);
    }
    int ok = 0;
    for (const PlacementResult& p : r.placements) {
      json pj = {{"name", p.name},         {"model", p.model},       {"status", p.status},
                 {"reason", p.reason},     {"truth", p.truth},       {"plan_seconds", p.plan_seconds},
                 {"sampled", p.sampled},   {"candidates_tried", p.candidates_tried}};
      ++attempted;
      plan_ms.push_back(p.plan_seconds * 1e3);
      if (p.status == "ok" && p.executed) {
        ++placed;
        ++ok;
        pj["place_t_err_mm"] = p.place_t_err_mm;
        pj["place_r_err_deg"] = p.place_r_err_deg;
        pj["offset_mm"] = {p.offset_mm.x(), p.offset_mm.y(), p.offset_mm.z()};
        pj["rotation_deg"] = {p.rotation_deg.x(), p.rotation_deg.y(), p.rotation_deg.z()};
        pj["motion_seconds"] = p.motion_seconds;
        offsets[p.model].push_back(p.offset_mm);
        rotations[p.model].push_back(p.rotation_deg);
        terr[p.model].push_back(p.place_t_err_mm);
        rerr[p.model].push_back(p.place_r_err_deg);
      }
      cj["placements"].push_back(pj);
    }
    out["cycles"].push_back(cj);
    std::printf("cycle %d (seed %llu): %zu located, %d placed of %zu, scan %.1f s, locate %.2f s, plan %.0f ms", c + 1,
                static_cast<unsigned long long>(seed), r.located, ok, r.placements.size(), r.scan_seconds,
                r.locate_seconds, r.plan_seconds * 1e3);
    if (!cfg.refine_trajectory.empty())
      std::printf(", second scan %.1f s, %zu of %zu refined in %.2f s", r.refine_scan_seconds, r.refined, r.located,
                  r.refine_seconds);
    std::printf("\n");
    for (const auto& w : r.refine_warnings) std::printf("  refine: %s\n", w.c_str());
    std::fflush(stdout);
  }
  // per-axis sample standard deviations (and the mean) of a model's vectors over the cycles
  auto spread = [](const std::vector<Eigen::Vector3d>& v, Eigen::Vector3d* mean) {
    Eigen::Vector3d sd;
    mean->setZero();
    for (int a = 0; a < 3; ++a) {
      std::vector<double> x;
      for (const auto& e : v) {
        x.push_back(e[a]);
        (*mean)[a] += e[a] / static_cast<double>(v.size());
      }
      sd[a] = stddev(x);
    }
    return sd;
  };
  json parts = json::object();
  double worst_sigma_mm = 0, worst_sigma_deg = 0;
  for (const auto& [model, offs] : offsets) {
    Eigen::Vector3d mean_t, mean_r;
    const Eigen::Vector3d sd_t = spread(offs, &mean_t), sd_r = spread(rotations[model], &mean_r);
    worst_sigma_mm = std::max(worst_sigma_mm, sd_t.maxCoeff());
    worst_sigma_deg = std::max(worst_sigma_deg, sd_r.maxCoeff());
    parts[model] = {{"placements", offs.size()},
                    {"sigma_mm", {sd_t.x(), sd_t.y(), sd_t.z()}},
                    {"sigma_deg", {sd_r.x(), sd_r.y(), sd_r.z()}},
                    {"mean_offset_mm", {mean_t.x(), mean_t.y(), mean_t.z()}},
                    {"median_t_err_mm", median(terr[model])},
                    {"max_t_err_mm", *std::max_element(terr[model].begin(), terr[model].end())},
                    {"median_r_err_deg", median(rerr[model])},
                    {"max_r_err_deg", *std::max_element(rerr[model].begin(), rerr[model].end())}};
  }
  // where the placement scatter comes from: the located poses' own scatter (picked and base part)
  std::printf("localisation over the cycles (located vs true pose, base frame):\n");
  for (const auto& [model, offs] : loc_offsets) {
    Eigen::Vector3d mean_t, mean_r;
    const Eigen::Vector3d sd_t = spread(offs, &mean_t), sd_r = spread(loc_rotations[model], &mean_r);
    parts[model]["locate_sigma_mm"] = {sd_t.x(), sd_t.y(), sd_t.z()};
    parts[model]["locate_sigma_deg"] = {sd_r.x(), sd_r.y(), sd_r.z()};
    parts[model]["locate_mean_offset_mm"] = {mean_t.x(), mean_t.y(), mean_t.z()};
    parts[model]["locate_mean_rotation_deg"] = {mean_r.x(), mean_r.y(), mean_r.z()};
    std::printf("  %-14s n %2zu  sigma %.3f %.3f %.3f mm  %.3f %.3f %.3f deg  mean %+.3f %+.3f %+.3f mm  %+.3f %+.3f %+.3f deg\n",
                model.c_str(), offs.size(), sd_t.x(), sd_t.y(), sd_t.z(), sd_r.x(), sd_r.y(), sd_r.z(), mean_t.x(),
                mean_t.y(), mean_t.z(), mean_r.x(), mean_r.y(), mean_r.z());
  }
  out["parts"] = parts;
  out["placed"] = placed;
  out["attempted"] = attempted;
  out["success_rate"] = attempted ? static_cast<double>(placed) / attempted : 0.0;
  out["worst_sigma_mm"] = worst_sigma_mm;
  out["worst_sigma_deg"] = worst_sigma_deg;
  out["median_plan_ms"] = median(plan_ms);
  out["max_plan_ms"] = plan_ms.empty() ? 0.0 : *std::max_element(plan_ms.begin(), plan_ms.end());
  out["sigma_note"] = "sample standard deviation over the cycles of the placed centroid (per base axis) and of the "
                      "rotation vector (per axis, symmetry removed), per model; worst_* = the largest over models and axes";
  json failed = json::array();
  char buf[200];
  if (o.limit_sigma_mm > 0 && worst_sigma_mm > o.limit_sigma_mm) {
    std::snprintf(buf, sizeof buf, "placement sigma %.3f mm > %.3f mm", worst_sigma_mm, o.limit_sigma_mm);
    failed.push_back(buf);
  }
  if (o.limit_sigma_deg > 0 && worst_sigma_deg > o.limit_sigma_deg) {
    std::snprintf(buf, sizeof buf, "placement sigma %.4f deg > %.4f deg", worst_sigma_deg, o.limit_sigma_deg);
    failed.push_back(buf);
  }
  if (o.limit_median_plan_ms > 0 && median(plan_ms) > o.limit_median_plan_ms) {
    std::snprintf(buf, sizeof buf, "median planning time %.1f ms > %.1f ms", median(plan_ms), o.limit_median_plan_ms);
    failed.push_back(buf);
  }
  double worst_t = 0;
  for (const auto& [model, e] : terr) worst_t = std::max(worst_t, *std::max_element(e.begin(), e.end()));
  out["max_t_err_mm"] = worst_t;
  if (o.limit_max_mm > 0 && worst_t > o.limit_max_mm) {
    std::snprintf(buf, sizeof buf, "largest placement error %.4f mm > %.4f mm", worst_t, o.limit_max_mm);
    failed.push_back(buf);
  }
  if (o.limit_success > 0 && out["success_rate"].get<double>() < o.limit_success) {
    std::snprintf(buf, sizeof buf, "placed %d of %d < %.3f", placed, attempted, o.limit_success);
    failed.push_back(buf);
  }
  out["limits_failed"] = failed;
  writeJson(o.json_path, out);
  std::printf("cycles: %d, placed %d/%d, worst sigma %.3f mm %.4f deg, median plan %.1f ms (max %.1f)\n", o.cycles, placed,
              attempted, worst_sigma_mm, worst_sigma_deg, median(plan_ms), out["max_plan_ms"].get<double>());
  for (const auto& f : failed) std::printf("LIMIT FAILED: %s\n", f.get<std::string>().c_str());
  return failed.empty() ? 0 : 3;
}

struct ReachOptions {
  std::string root = ".", scene = "config/scenes/demo.yaml", json_path;
  double step = 0.05;
};

int runReach(const ReachOptions& o) {
  const Scene scene = loadScene(o.scene[0] == '/' ? o.scene : o.root + "/" + o.scene);
  const ArmModel arm = ArmModel::fromUrdfFile(o.root + "/urdf/cellsight_arm.urdf");
  const AssemblyConfig as = loadAssemblyConfig(o.root + "/config/assembly.yaml");
  const Eigen::Isometry3d tcp_tool0 = arm.toolTcp().inverse();
  json rows = json::array();
  for (double tilt_deg : {0.0, 30.0, 60.0}) {
    for (double h : {0.01, 0.05, 0.10}) {
      int total = 0, ok = 0;
      for (double x = scene.table.center.x() - scene.table.size.x() / 2 + o.step / 2;
           x < scene.table.center.x() + scene.table.size.x() / 2; x += o.step) {
        for (double y = scene.table.center.y() - scene.table.size.y() / 2 + o.step / 2;
             y < scene.table.center.y() + scene.table.size.y() / 2; y += o.step) {
          // the tool pointing down, tilted about the tool's y; jaws at 0 and 90 deg; any of them counts
          bool any = false;
          for (double yaw : {0.0, M_PI / 2, M_PI, -M_PI / 2}) {
            Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
            T.translation() = Eigen::Vector3d(x, y, scene.table.z + h);
            T.linear() = (Eigen::AngleAxisd(yaw, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()) *
                          Eigen::AngleAxisd(tilt_deg * M_PI / 180, Eigen::Vector3d::UnitY()))
                             .toRotationMatrix();
            if (arm.ik(T * tcp_tool0, as.home)) {
              any = true;
              break;
            }
          }
          ++total;
          ok += any;
        }
      }
      rows.push_back({{"tilt_deg", tilt_deg}, {"tcp_height_m", h}, {"cells", total}, {"reachable", ok},
                      {"share", total ? static_cast<double>(ok) / total : 0.0}});
      std::printf("tilt %2.0f deg, tcp %.2f m above the table: %d of %d cells reachable (%.0f %%)\n", tilt_deg, h, ok, total,
                  100.0 * ok / std::max(1, total));
    }
  }
  json out = {{"scene", o.scene}, {"grid_step_m", o.step}, {"table_center", {scene.table.center.x(), scene.table.center.y()}},
              {"table_size", {scene.table.size.x(), scene.table.size.y()}}, {"rows", rows}};
  writeJson(o.json_path, out);
  return 0;
}

struct DemoOptions {
  std::string root = ".", scene = "config/scenes/demo.yaml", assembly, truth, json_path;
};

/// The demo's assembly against the simulator's truth: every step of assembly_client, the part
/// cell_sim put down for it, and the error against the target (true base part · T_0i). Exit 3
/// when a planned part was not executed or has no truth.
int runDemo(const DemoOptions& o) {
  const Scene scene = loadScene(o.scene[0] == '/' ? o.scene : o.root + "/" + o.scene);
  const AssemblyConfig as = loadAssemblyConfig(o.root + "/config/assembly.yaml");
  std::ifstream in(o.assembly);
  if (!in) throw std::runtime_error(o.assembly + ": cannot read the assembly steps");
  const json steps = json::parse(in).at("steps");
  std::map<std::string, json> truth;  // by plan object
  std::ifstream tl(o.truth);
  if (!tl) throw std::runtime_error(o.truth + ": cannot read the placements' truth");
  for (std::string line; std::getline(tl, line);) {
    if (line.empty()) continue;
    const json j = json::parse(line);
    truth[j.at("plan_object").get<std::string>()] = j;
  }
  const SceneObject* base = nullptr;
  for (const auto& ob : scene.objects) {
    if (ob.model == as.base_model) base = &ob;
  }
  if (!base) throw std::runtime_error(o.scene + ": no '" + as.base_model + "' (the base part) in the scene");
  json placements = json::array();
  bool ok = true;
  std::vector<double> plan_ms;
  for (const auto& s : steps) {
    json p = {{"object", s.at("object")}, {"model", s.at("model")}, {"status", s.at("status")}, {"reason", s.at("reason")},
              {"plan_seconds", s.at("plan_seconds")}, {"executed", s.value("executed", false)}};
    // status: GraspPlan's code (0 = OK), or the planner's name of a refusal for parts passed over
    const bool is_ok = s.at("status").is_number() && s.at("status").get<int>() == 0;
    if (is_ok) plan_ms.push_back(s.at("plan_seconds").get<double>() * 1e3);
    p["status"] = is_ok ? json("ok") : s.at("status").is_string() ? s.at("status") : json("refused");
    if (s.value("executed", false)) {
      const auto it = truth.find(s.at("object").get<std::string>());
      if (it == truth.end()) {
        p["place_t_err_mm"] = nullptr;
        p["place_r_err_deg"] = nullptr;
        p["note"] = "no part was put down for it (the jaws closed on nothing)";
        ok = false;
      } else {
        const std::string model = it->second.at("model");
        const SceneObject* obj = nullptr;
        for (const auto& ob : scene.objects) {
          if (ob.name == it->second.at("object").get<std::string>()) obj = &ob;
        }
        if (!obj) throw std::runtime_error("the truth names object '" + it->second.at("object").get<std::string>() + "', not in the scene");
        const TriangleMesh mesh = loadMesh(obj->info.mesh_file);
        const Eigen::Isometry3d placed = cellsight_tools::poseFromJson(it->second.at("pose"));
        const Eigen::Isometry3d target = base->T_base_object * obj->info.T_0i;
        const PoseError e = poseError(obj->info, mesh.surfaceCentroid(), placed, target);
        Eigen::Vector3d off, rot;
        placementDeviation(obj->info, mesh.surfaceCentroid(), placed, target, &off, &rot);
        p["truth"] = obj->name;
        p["place_t_err_mm"] = e.translation * 1e3;
        p["place_r_err_deg"] = e.rotation * 180 / M_PI;
        p["offset_mm"] = {off.x() * 1e3, off.y() * 1e3, off.z() * 1e3};
        p["motion_seconds"] = s.value("motion_seconds", 0.0);
        if (obj->model != s.at("model").get<std::string>()) {
          p["note"] = "the part picked is a " + obj->model + ", not the planned " + s.at("model").get<std::string>();
          ok = false;
        }
      }
    } else if (is_ok) {
      ok = false;  // planned but not executed
    }
    placements.push_back(p);
  }
  json out = {{"placements", placements}, {"median_plan_ms", median(plan_ms)}, {"ok", ok}};
  writeJson(o.json_path, out);
  for (const auto& p : placements) {
    if (p.value("executed", false) && !p["place_t_err_mm"].is_null()) {
      std::printf("placed %s: %.3f mm, %.3f deg from its target (plan %.0f ms)\n", p["object"].get<std::string>().c_str(),
                  p["place_t_err_mm"].get<double>(), p["place_r_err_deg"].get<double>(), p["plan_seconds"].get<double>() * 1e3);
    } else {
      std::printf("%s %s: %s\n", p["status"].get<std::string>().c_str(), p["object"].get<std::string>().c_str(),
                  p["reason"].get<std::string>().c_str());
    }
  }
  return ok ? 0 : 3;
}

}  // namespace

int main(int argc, char** argv) {
  CLI::App app("Grasp and assembly planning figures: full cell cycles against the simulator's truth, reachability.",
               "cellsight_plan");
  app.require_subcommand(1);
  CyclesOptions co;
  auto* cycles = app.add_subcommand("cycles", "full cell cycles in-process: scan, locate, plan, execute; placement error vs the truth");
  cycles->add_option("--root", co.root, "the package folder (config/, urdf/)")->capture_default_str();
  cycles->add_option("--scene", co.scene, "scene file (relative to --root unless absolute)")->capture_default_str();
  cycles->add_option("--calibration", co.calibration,
                     "calibration folder the scanner uses (the user's cell's); without it, the simulator's truth");
  cycles->add_option("--cycles", co.cycles, "cycles, each with fresh image noise and robot scatter")
      ->check(cellsight_tools::positiveInt())->capture_default_str();
  cycles->add_option("--first-seed", co.first_seed, "noise seed of the first cycle")->check(cellsight_tools::nonNegativeInt())
      ->capture_default_str();
  cycles->add_option("--json", co.json_path, "write the figures here");
  cycles->add_option("--dump-scans", co.dump_scans, "write every cycle's finished scan here (scan_<seed>.ply)")
      ->check(CLI::ExistingDirectory);
  cycles->add_option("--trajectory", co.trajectory, "the scan's trajectory (config/trajectories.yaml)")->capture_default_str();
  cycles->add_option("--refine-trajectory", co.refine_trajectory,
                     "a second pass along this trajectory refines the located parts on both scans (none: one pass)")
      ->capture_default_str();
  cycles->add_option("--limit-sigma-mm", co.limit_sigma_mm, "exit 3 when a placement sigma exceeds this (mm)")
      ->check(cellsight_tools::nonNegative());
  cycles->add_option("--limit-sigma-deg", co.limit_sigma_deg, "exit 3 when a rotation sigma exceeds this (deg)")
      ->check(cellsight_tools::nonNegative());
  cycles->add_option("--limit-median-plan-ms", co.limit_median_plan_ms, "exit 3 when the median planning time per part exceeds this")
      ->check(cellsight_tools::nonNegative());
  cycles->add_option("--limit-max-mm", co.limit_max_mm, "exit 3 when a placement error exceeds this (mm)")
      ->check(cellsight_tools::nonNegative());
  cycles->add_option("--limit-success", co.limit_success, "exit 3 when fewer placements than this share succeed")
      ->check(cellsight_tools::fraction());
  cycles->add_flag("--exact-robot", co.exact_robot,
                   "error budget: execute with a robot without kinematic error (the scan still uses the real one)");
  cycles->add_flag("--true-poses", co.true_poses, "error budget: plan on the true part poses instead of the located ones");
  ReachOptions ro;
  auto* reach = app.add_subcommand("reach", "reachability of the table for the tool pointing down and tilted");
  reach->add_option("--root", ro.root, "the package folder")->capture_default_str();
  reach->add_option("--scene", ro.scene, "scene file (its table)")->capture_default_str();
  reach->add_option("--step", ro.step, "grid step (m)")->check(cellsight_tools::positive())->capture_default_str();
  reach->add_option("--json", ro.json_path, "write the table here");
  DemoOptions dopt;
  auto* demo = app.add_subcommand("demo", "the demo's assembly (assembly_client steps + cell_sim truth) against the targets");
  demo->add_option("--root", dopt.root, "the package folder")->capture_default_str();
  demo->add_option("--scene", dopt.scene, "scene file")->capture_default_str();
  demo->add_option("--assembly", dopt.assembly, "assembly_client's result file (assembly.json)")->required();
  demo->add_option("--truth", dopt.truth, "cell_sim's truth/placements.jsonl")->required();
  demo->add_option("--json", dopt.json_path, "write the placements here");
  if (const auto rc = cellsight_tools::parse(app, argc, argv)) return *rc;
  return cellsight_tools::runTool([&] {
    if (cycles->parsed()) return runCycles(co);
    if (demo->parsed()) return runDemo(dopt);
    return runReach(ro);
  });
}
