// Planning speed and quality against peers, one core: the demo cell's whole assembly (four parts,
// each planned from where the last one left the robot, the world updated after each) in
// `scenarios` variants: the parts shifted and turned (seeded) and an unknown box of scan points
// (8 to 15 cm high) standing somewhere on the table, so that straight joint moves often collide.
// Methods, on the same scenarios:
//   cellsight          the straight joint edge first, else OMPL RRTConnect + OMPL's PathSimplifier
//   rrtconnect_raw     OMPL RRTConnect on every joint segment, no simplification
//   rrt_raw            OMPL RRT, no simplification
//   straight           straight joint interpolation, rejected when it collides (no sampling)
// Every plan's joint segments are re-checked densely (0.001 rad, the bare shapes without padding); a plan that fails it, a refusal or an exception
// is a failure. Times are compared only over the parts every method planned.
// Usage: bench_planning <out.json> [scenarios]
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <map>
#include <nlohmann/json.hpp>
#include <random>

#include "cellsight/planning/grasp_planner.hpp"
#include "cellsight/sim/scene.hpp"

using namespace cellsight;
using json = nlohmann::json;

namespace {

struct Scenario {
  std::vector<LocatedPart> parts;
  std::vector<Eigen::Vector3f> scan;
};

std::vector<Eigen::Vector3f> boxSurface(const Eigen::Vector3d& lo, const Eigen::Vector3d& hi, double step) {
  std::vector<Eigen::Vector3f> pts;
  for (double x = lo.x(); x <= hi.x() + 1e-9; x += step)
    for (double y = lo.y(); y <= hi.y() + 1e-9; y += step)
      for (double z = lo.z(); z <= hi.z() + 1e-9; z += step)
        if (x - lo.x() < step || hi.x() - x < step || y - lo.y() < step || hi.y() - y < step || hi.z() - z < step)
          pts.emplace_back(Eigen::Vector3f(x, y, z));
  return pts;
}

Scenario makeScenario(const Scene& scene, const AssemblyConfig& as, uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> u(-1, 1);
  Scenario s;
  for (int attempt = 0; attempt < 200; ++attempt) {
    s.parts.clear();
    for (const auto& o : scene.objects) {
      Eigen::Isometry3d T = o.T_base_object;
      if (seed > 0) {
        T.translation() += Eigen::Vector3d(0.015 * u(rng), 0.015 * u(rng), 0);
        T.linear() = Eigen::AngleAxisd(0.5 * u(rng), Eigen::Vector3d::UnitZ()).toRotationMatrix() * T.linear();
      }
      s.parts.push_back({o.name, o.model, T, {}});
    }
    // parts (bounding circles of 45 mm) must not overlap
    bool ok = true;
    for (size_t i = 0; i < s.parts.size() && ok; ++i)
      for (size_t k = i + 1; k < s.parts.size(); ++k)
        if ((s.parts[i].pose.translation() - s.parts[k].pose.translation()).head<2>().norm() < 0.06) ok = false;
    if (ok) break;
  }
  if (seed == 0) return s;
  // the unknown box: away from the parts and from the assembly's targets
  std::vector<Eigen::Vector2d> keep_out;
  const LocatedPart* base = nullptr;
  for (const auto& p : s.parts) {
    keep_out.push_back(p.pose.translation().head<2>());
    if (p.model == as.base_model) base = &p;
  }
  for (const auto& o : scene.objects) keep_out.push_back((base->pose * o.info.T_0i).translation().head<2>());
  std::uniform_real_distribution<double> ux(0.25, 0.70), uy(-0.25, 0.25), uh(0.08, 0.15);
  for (int attempt = 0; attempt < 500; ++attempt) {
    const Eigen::Vector2d c(ux(rng), uy(rng));
    bool clear = true;
    for (const auto& k : keep_out) clear = clear && (k - c).norm() > 0.085;
    if (!clear) continue;
    const double h = uh(rng);
    s.scan = boxSurface(Eigen::Vector3d(c.x() - 0.02, c.y() - 0.02, 0.004), Eigen::Vector3d(c.x() + 0.02, c.y() + 0.02, h), 0.002);
    break;
  }
  return s;
}

double median(std::vector<double> v) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

double percentile(std::vector<double> v, double q) {
  if (v.empty()) return 0;
  std::sort(v.begin(), v.end());
  return v[std::min(v.size() - 1, static_cast<size_t>(q * static_cast<double>(v.size())))];
}

struct PartResult {
  bool ok = false;
  double seconds = 0, joint_path = 0, motion = 0;
  std::string reason;
};

}  // namespace

int main(int argc, char** argv) {
  if (argc < 2) {
    std::fprintf(stderr, "usage: bench_planning <out.json> [scenarios]\n");
    return 2;
  }
  const int scenarios = argc > 2 ? std::max(1, std::atoi(argv[2])) : 20;
  const std::string root = CELLSIGHT_SOURCE_DIR;
  const Scene scene = loadScene(root + "/config/scenes/demo.yaml");
  const ArmModel arm = ArmModel::fromUrdfFile(root + "/urdf/cellsight_arm.urdf");
  const AssemblyConfig as = loadAssemblyConfig(root + "/config/assembly.yaml");
  std::map<std::string, std::pair<ModelInfo, std::shared_ptr<const TriangleMesh>>> models;
  for (const auto& o : scene.objects) models[o.model] = {o.info, std::make_shared<TriangleMesh>(loadMesh(o.info.mesh_file))};
  struct Method {
    std::string name, what;
    MotionPlannerConfig cfg;
  };
  std::vector<Method> methods(4);
  methods[0] = {"cellsight", "straight joint edge first, else RRTConnect + PathSimplifier", {}};
  methods[1] = {"rrtconnect_raw", "OMPL RRTConnect on every joint segment, no simplification", {}};
  methods[1].cfg.direct_first = false;
  methods[1].cfg.simplify = false;
  methods[2] = {"rrt_raw", "OMPL RRT on every joint segment, no simplification", {}};
  methods[2].cfg.direct_first = false;
  methods[2].cfg.simplify = false;
  methods[2].cfg.planner = "rrt";
  methods[3] = {"straight", "straight joint interpolation, rejected when it collides", {}};
  methods[3].cfg.planner = "straight";
  // results[method][scenario * 10 + part]
  std::map<std::string, std::map<int, PartResult>> results;
  const MotionPlanner checker(arm, MotionPlannerConfig{});
  for (const Method& m : methods) {
    GraspPlanner gp(arm, as, GripperConfig{}, m.cfg, models);
    for (const auto& [id, mm] : models) gp.candidates(id);  // grasp candidates are per model, not per plan
    for (int sc = 0; sc < scenarios; ++sc) {
      const Scenario s = makeScenario(scene, as, static_cast<uint64_t>(sc));
      gp.setScene(CollisionWorld(CollisionWorldConfig{}, scene.table.z, scene.table.center, scene.table.size), s.parts, s.scan);
      JointVector q = as.home;
      for (size_t k = 0; k < as.order.size(); ++k) {
        size_t idx = s.parts.size();
        for (size_t i = 0; i < s.parts.size(); ++i)
          if (s.parts[i].model == as.order[k]) idx = i;
        PartResult r;
        PartPlan p;
        try {
          p = gp.plan(idx, q);
          r.seconds = p.seconds;
          r.ok = p.status == PlanStatus::kOk;
          r.reason = p.reason;
        } catch (const std::exception& e) {
          r.reason = std::string("exception: ") + e.what();
        }
        if (r.ok) {
          // the dense re-check of the joint segments (the Cartesian ones are checked at every IK step)
          CollisionWorld bare(gp.world());
          bare.setPadding(0);
          CollisionWorld w_carry(bare);
          w_carry.removeObject(static_cast<int>(idx));
          const CarriedPart carried{models.at(p.part.model).second, p.poses[1].T_base_tcp.inverse() * p.part.pose, p.part.name};
          for (const PlanSegment& seg : p.segments) {
            if (seg.cartesian) continue;
            const CollisionContext ctx{seg.carrying ? &w_carry : &bare, seg.opening, seg.carrying ? &carried : nullptr, -1};
            CollisionReport where;
            if (!checker.pathValid(seg.path, ctx, 0.001, &where)) {
              r.ok = false;
              r.reason = "dense re-check: " + where.text();
            }
            for (size_t i = 1; i < seg.path.size(); ++i) r.joint_path += (seg.path[i] - seg.path[i - 1]).norm();
          }
          r.motion = p.trajectory.duration();
        }
        results[m.name][sc * 10 + static_cast<int>(k)] = r;
        if (std::getenv("BENCH_VERBOSE")) {
          std::printf("%s scenario %d %s: %s %.1f ms, %d tried, sampled %d\n", m.name.c_str(), sc, as.order[k].c_str(),
                      r.ok ? "ok" : "FAILED", r.seconds * 1e3, p.candidates_tried, static_cast<int>(p.sampled));
        }
        if (r.ok) {
          gp.commit(idx, p);
          q = p.poses.back().q;
        }
      }
    }
  }
  // every method's figures over the parts all of them planned
  std::vector<int> common;
  for (const auto& [key, r] : results[methods[0].name]) {
    bool all = true;
    for (const Method& m : methods) all = all && results[m.name][key].ok;
    if (all) common.push_back(key);
  }
  json out = {{"scenarios", scenarios}, {"parts_per_scenario", as.order.size()}, {"common_parts", common.size()},
              {"recheck_resolution_rad", 0.001}, {"methods", json::array()}};
  std::printf("%-16s %8s %10s %10s %10s %12s %10s\n", "method", "planned", "median ms", "p90 ms", "common ms", "joint path", "motion s");
  for (const Method& m : methods) {
    std::vector<double> t, tc, len, mot;
    int ok = 0, total = 0;
    std::map<std::string, int> failures;
    for (const auto& [key, r] : results[m.name]) {
      ++total;
      if (r.ok) {
        ++ok;
        t.push_back(r.seconds * 1e3);
      } else {
        ++failures[r.reason.substr(0, 60)];
      }
    }
    for (int key : common) {
      const PartResult& r = results[m.name][key];
      tc.push_back(r.seconds * 1e3);
      len.push_back(r.joint_path);
      mot.push_back(r.motion);
    }
    json f = json::object();
    for (const auto& [why, n] : failures) f[why] = n;
    out["methods"].push_back({{"name", m.name},
                              {"what", m.what},
                              {"planned", ok},
                              {"attempted", total},
                              {"median_plan_ms", median(t)},
                              {"p90_plan_ms", percentile(t, 0.9)},
                              {"common_median_plan_ms", median(tc)},
                              {"common_median_joint_path_rad", median(len)},
                              {"common_median_motion_s", median(mot)},
                              {"failures", f}});
    std::printf("%-16s %4d/%-3d %10.1f %10.1f %10.1f %12.2f %10.2f\n", m.name.c_str(), ok, total, median(t), percentile(t, 0.9),
                median(tc), median(len), median(mot));
  }
  std::ofstream(argv[1]) << out.dump(2) << "\n";
  return 0;
}
