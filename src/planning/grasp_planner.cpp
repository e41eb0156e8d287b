#include "cellsight/planning/grasp_planner.hpp"

#include <algorithm>
#include <chrono>
#include <cmath>
#include <stdexcept>

#include "cellsight/common/yaml_reader.hpp"

namespace cellsight {

namespace {

double now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

Eigen::Isometry3d alongZ(double d) { return Eigen::Isometry3d(Eigen::Translation3d(0, 0, d)); }

}  // namespace

const char* planStatusName(PlanStatus s) {
  switch (s) {
    case PlanStatus::kOk: return "ok";
    case PlanStatus::kUnknownModel: return "unknown_model";
    case PlanStatus::kNotInAssembly: return "not_in_assembly";
    case PlanStatus::kBasePart: return "base_part";
    case PlanStatus::kNoBase: return "no_base_part";
    case PlanStatus::kNoGrasp: return "no_grasp";
    case PlanStatus::kUnreachable: return "unreachable";
    case PlanStatus::kNoPath: return "no_path";
    case PlanStatus::kBadInput: return "bad_input";
    case PlanStatus::kNothingLeft: return "nothing_left";
    case PlanStatus::kAmbiguousPose: return "ambiguous_pose";
  }
  return "?";
}

AssemblyConfig loadAssemblyConfig(const std::string& path) {
  const YAML::Node root = loadYamlFile(path);
  YamlMap m(root, path);
  AssemblyConfig c;
  c.base_model = m.getString("base_model");
  const YAML::Node& order = m.raw("order");
  if (!order.IsSequence() || order.size() == 0) m.fail("order", "a non-empty list of model ids");
  for (const auto& o : order) c.order.push_back(o.as<std::string>());
  c.approach_distance = m.getDouble("approach_distance", c.approach_distance);
  c.lift_height = m.getDouble("lift_height", c.lift_height);
  c.preplace_distance = m.getDouble("preplace_distance", c.preplace_distance);
  c.retreat_distance = m.getDouble("retreat_distance", c.retreat_distance);
  c.insert_contact_distance = m.getDouble("insert_contact_distance", c.insert_contact_distance);
  c.placed_tolerance = m.getDouble("placed_tolerance", c.placed_tolerance);
  c.placed_tolerance_rad = m.getDouble("placed_tolerance_rad", c.placed_tolerance_rad);
  c.min_approach_down = m.getDouble("min_approach_down", c.min_approach_down);
  c.max_candidates = m.getInt("max_candidates", c.max_candidates);
  if (m.has("home")) {
    const auto h = m.getDoubles("home", 6);
    for (int i = 0; i < 6; ++i) c.home[i] = h[static_cast<size_t>(i)];
  }
  m.finish();
  for (const char* key : {"approach_distance", "lift_height", "preplace_distance", "retreat_distance"}) {
    const double v = key == std::string("approach_distance") ? c.approach_distance
                     : key == std::string("lift_height")     ? c.lift_height
                     : key == std::string("preplace_distance") ? c.preplace_distance
                                                               : c.retreat_distance;
    if (!(v > 0 && v < 0.5)) m.fail(key, "must be in (0, 0.5) m");
  }
  if (!(c.insert_contact_distance >= 0 && c.insert_contact_distance < c.preplace_distance)) {
    m.fail("insert_contact_distance", "must be in [0, preplace_distance)");
  }
  if (!(c.placed_tolerance > 0) || !(c.placed_tolerance_rad > 0)) m.fail("placed_tolerance", "tolerances must be > 0");
  if (c.max_candidates < 1) m.fail("max_candidates", "must be >= 1");
  if (std::find(c.order.begin(), c.order.end(), c.base_model) != c.order.end()) {
    m.fail("order", "must not hold the base model '" + c.base_model + "' (it stays where it lies)");
  }
  return c;
}

GraspPlanner::GraspPlanner(const ArmModel& arm, const AssemblyConfig& assembly, const GripperConfig& gripper,
                           const MotionPlannerConfig& motion,
                           std::map<std::string, std::pair<ModelInfo, std::shared_ptr<const TriangleMesh>>> models)
    : arm_(arm), assembly_(assembly), gripper_(gripper), motion_(arm, motion), models_(std::move(models)) {
  if (!models_.count(assembly_.base_model)) {
    throw std::invalid_argument("grasp planner: the assembly's base model '" + assembly_.base_model + "' is not in the model library");
  }
  for (const auto& m : assembly_.order) {
    if (!models_.count(m)) throw std::invalid_argument("grasp planner: the assembly's model '" + m + "' is not in the model library");
  }
  gripper_.max_opening = std::min(gripper_.max_opening, arm.maxJawOpening());
}

const std::vector<GraspCandidate>& GraspPlanner::candidates(const std::string& model) const {
  auto it = candidates_.find(model);
  if (it != candidates_.end()) return it->second;
  const auto& [info, mesh] = models_.at(model);
  return candidates_[model] = graspCandidates(info, *mesh, gripper_);
}

void GraspPlanner::setScene(CollisionWorld world, const std::vector<LocatedPart>& parts,
                            const std::vector<Eigen::Vector3f>& scan) {
  world_ = std::make_unique<CollisionWorld>(world);
  parts_ = parts;
  object_ids_.clear();
  placed_.clear();
  skipped_.clear();
  for (const LocatedPart& p : parts_) {
    auto it = models_.find(p.model);
    object_ids_.push_back(it == models_.end() || !p.pose.matrix().allFinite() ? -1
                                                                              : world_->addObject(p.name, it->second.second, p.pose));
  }
  world_->setScan(scan);
  // lying at its target already: known only with the base part's pose unambiguous, and then
  // only where every pose the scan leaves the part (Detection.ambiguous_poses) is at the target
  size_t base = parts_.size();
  for (size_t i = 0; i < parts_.size(); ++i) {
    if (parts_[i].model == assembly_.base_model && object_ids_[i] >= 0 && base == parts_.size()) base = i;
  }
  if (base == parts_.size() || !parts_[base].ambiguous_poses.empty()) return;
  for (size_t i = 0; i < parts_.size(); ++i) {
    auto it = models_.find(parts_[i].model);
    if (i == base || it == models_.end()) continue;
    const ModelInfo& info = it->second.first;
    const Eigen::Isometry3d target = parts_[base].pose * info.T_0i;
    const Eigen::Vector3d c = it->second.second->surfaceCentroid();
    const auto symmetry = symmetryRotations(info, 72, c);
    auto atTarget = [&](const Eigen::Isometry3d& pose) {
      if ((pose * c - target * c).norm() > assembly_.placed_tolerance) return false;
      return std::any_of(symmetry.begin(), symmetry.end(), [&](const Eigen::Isometry3d& S) {
        return Eigen::AngleAxisd(pose.linear().transpose() * (target * S).linear()).angle() <= assembly_.placed_tolerance_rad;
      });
    };
    if (atTarget(parts_[i].pose) && std::all_of(parts_[i].ambiguous_poses.begin(), parts_[i].ambiguous_poses.end(), atTarget))
      placed_[i] = 1;
  }
}

PartPlan GraspPlanner::plan(size_t index, const JointVector& start) const {
  const double t0 = now();
  PartPlan p;
  auto finish = [&](PlanStatus s, const std::string& reason) {
    p.status = s;
    p.reason = reason;
    p.seconds = now() - t0;
    return p;
  };
  if (!world_) return finish(PlanStatus::kBadInput, "no scene: call setScene first");
  if (index >= parts_.size()) return finish(PlanStatus::kBadInput, "no located part " + std::to_string(index));
  p.part = parts_[index];
  if (!start.allFinite() || !arm_.withinLimits(start)) {
    return finish(PlanStatus::kBadInput, "the start joint state is not finite or outside the joint limits");
  }
  if (!p.part.pose.matrix().allFinite()) return finish(PlanStatus::kBadInput, "the part's pose is not finite");
  auto mit = models_.find(p.part.model);
  if (mit == models_.end()) return finish(PlanStatus::kUnknownModel, "model '" + p.part.model + "' is not in the model library");
  if (p.part.model == assembly_.base_model) return finish(PlanStatus::kBasePart, "the base part stays where it lies");
  if (std::find(assembly_.order.begin(), assembly_.order.end(), p.part.model) == assembly_.order.end()) {
    return finish(PlanStatus::kNotInAssembly, "model '" + p.part.model + "' is not in the assembly's order");
  }
  if (placed_.count(index)) return finish(PlanStatus::kBadInput, "part '" + p.part.name + "' is already placed");
  size_t base = parts_.size();
  for (size_t i = 0; i < parts_.size(); ++i) {
    if (parts_[i].model == assembly_.base_model && object_ids_[i] >= 0) {
      base = i;
      break;
    }
  }
  if (base == parts_.size()) return finish(PlanStatus::kNoBase, "the base part '" + assembly_.base_model + "' was not located");
  // a pose the scan cannot tell from another: the placement (which face goes where) is unknown
  auto ambiguous = [](const LocatedPart& part, const std::string& what) {
    return what + " '" + part.name + "' fits the scan turned about the table's normal as well (" +
           std::to_string(part.ambiguous_poses.size()) + " such pose(s), Detection.ambiguous_poses): turn it and scan again, or check its orientation";
  };
  if (!p.part.ambiguous_poses.empty()) return finish(PlanStatus::kAmbiguousPose, ambiguous(p.part, "the part"));
  if (!parts_[base].ambiguous_poses.empty())
    return finish(PlanStatus::kAmbiguousPose, ambiguous(parts_[base], "the base part, where the targets are,"));
  const ModelInfo& info = mit->second.first;
  const auto mesh = mit->second.second;
  const std::vector<GraspCandidate>& all = candidates(p.part.model);
  p.candidates = static_cast<int>(all.size());
  const double cone = std::atan(gripper_.friction);
  std::vector<std::pair<double, const GraspCandidate*>> ranked;
  std::map<std::string, int> measured;  // refused before planning: the jaws, the friction cone, the approach
  for (const GraspCandidate& c : all) {
    if (!c.valid) {
      ++measured[c.reason.substr(0, c.reason.find(" ("))];
      continue;
    }
    const Eigen::Isometry3d T = p.part.pose * c.T_model_tcp;
    const double down = -T.linear().col(2).z();
    if (down < assembly_.min_approach_down) {
      ++measured["approach from below the table"];
      continue;
    }
    const double score = down + 0.5 * (1 - std::min(1.0, c.centroid_distance / 0.05)) +
                         0.3 * std::clamp(c.friction_margin / std::max(cone, 1e-9), 0.0, 1.0) +
                         0.2 * (gripper_.max_opening - c.width - 2 * gripper_.clearance) / gripper_.max_opening +
                         (c.source.rfind("model", 0) == 0 ? 0.5 : 0.0);  // the part author's grasp first
    ranked.emplace_back(score, &c);
  }
  for (const auto& [r, n] : measured) p.pruned[r] += n;
  if (ranked.empty()) {
    std::string why;
    for (const auto& [r, n] : measured) why += (why.empty() ? "" : "; ") + r + " x" + std::to_string(n);
    return finish(PlanStatus::kNoGrasp, "no grasp candidate fits: " + (why.empty() ? std::string("none generated") : why));
  }
  std::stable_sort(ranked.begin(), ranked.end(), [](const auto& a, const auto& b) { return a.first > b.first; });

  const Eigen::Isometry3d T_base_part = parts_[base].pose;
  const Eigen::Isometry3d T_target = T_base_part * info.T_0i;
  const Eigen::Vector3d v = (T_base_part.linear() * info.assembly_direction).normalized();
  const auto sym = symmetryRotations(info, gripper_.axial_steps, mesh->surfaceCentroid());
  const int obj = object_ids_[index];
  const int base_obj = object_ids_[base];
  CollisionWorld w_carry(*world_);
  if (obj >= 0) w_carry.removeObject(obj);
  const Eigen::Isometry3d tcp_tool0 = arm_.toolTcp().inverse();
  auto tool0 = [&](const Eigen::Isometry3d& T_tcp) { return T_tcp * tcp_tool0; };
  bool any_reachable = false;
  for (const auto& [score, cand] : ranked) {
    if (p.candidates_tried >= assembly_.max_candidates) break;
    ++p.candidates_tried;
    const GraspCandidate& g = *cand;
    const double open = std::min(gripper_.max_opening, g.width + 2 * gripper_.clearance);
    const Eigen::Isometry3d T_grasp = p.part.pose * g.T_model_tcp;
    const Eigen::Isometry3d T_pre = T_grasp * alongZ(-assembly_.approach_distance);
    const Eigen::Isometry3d T_lift = Eigen::Translation3d(0, 0, assembly_.lift_height) * T_grasp;
    CollisionContext c_open{world_.get(), open, nullptr, -1};
    const auto q_pre = arm_.ik(tool0(T_pre), start);
    if (!q_pre) {
      ++p.pruned["pre-grasp unreachable"];
      continue;
    }
    const auto q_at_grasp = arm_.ik(tool0(T_grasp), *q_pre);
    if (!q_at_grasp) {
      ++p.pruned["grasp unreachable"];
      continue;
    }
    any_reachable = true;
    // the two ends first: cheaper than the straight line between them
    CollisionReport r = motion_.checkState(*q_at_grasp, c_open);
    if (r.collides) {
      ++p.pruned["grasp collides: " + r.text()];
      continue;
    }
    r = motion_.checkState(*q_pre, c_open);
    if (r.collides) {
      ++p.pruned["pre-grasp collides: " + r.text()];
      continue;
    }
    const PathResult approach = motion_.planCartesian(*q_pre, tool0(T_grasp), c_open);
    if (!approach.ok) {
      ++p.pruned["approach: " + approach.reason.substr(0, approach.reason.find(" at "))];
      continue;
    }
    const JointVector q_grasp = approach.waypoints.back();
    CarriedPart carried{mesh, T_grasp.inverse() * p.part.pose, p.part.name};
    CollisionContext c_carry{&w_carry, g.width, &carried, -1};
    const PathResult lift = motion_.planCartesian(q_grasp, tool0(T_lift), c_carry);
    if (!lift.ok) {
      ++p.pruned["lift: " + lift.reason.substr(0, lift.reason.find(" at "))];
      continue;
    }
    const JointVector q_lift = lift.waypoints.back();
    // the symmetry turn whose pre-place pose is nearest the lift in joint space
    std::optional<JointVector> q_pp;
    Eigen::Isometry3d T_place = Eigen::Isometry3d::Identity(), T_target_used = T_target;
    std::string pp_reason = "pre-place unreachable";
    for (const auto& S : sym) {
      const Eigen::Isometry3d Tp = T_target * S * g.T_model_tcp;
      const Eigen::Isometry3d Tpp = Eigen::Translation3d(-v * assembly_.preplace_distance) * Tp;
      const auto q = arm_.ik(tool0(Tpp), q_lift);
      if (!q) continue;
      r = motion_.checkState(*q, c_carry);
      if (r.collides) {
        pp_reason = "pre-place collides: " + r.text();
        continue;
      }
      if (!q_pp || jointDistance(*q, q_lift) < jointDistance(*q_pp, q_lift)) {
        q_pp = q;
        T_place = Tp;
        T_target_used = T_target * S;
      }
    }
    if (!q_pp) {
      ++p.pruned[pp_reason];
      continue;
    }
    // the insertion: checked against everything down to its last stretch, where the part may
    // touch the one it goes into
    const Eigen::Isometry3d T_contact = Eigen::Translation3d(-v * assembly_.insert_contact_distance) * T_place;
    PathResult insert = motion_.planCartesian(*q_pp, tool0(T_contact), c_carry);
    if (insert.ok) {
      CollisionContext c_insert{&w_carry, g.width, &carried, base_obj};
      const PathResult last = motion_.planCartesian(insert.waypoints.back(), tool0(T_place), c_insert);
      insert.ok = last.ok;
      insert.reason = last.reason;
      insert.waypoints.insert(insert.waypoints.end(), last.waypoints.begin() + 1, last.waypoints.end());
    }
    if (!insert.ok) {
      ++p.pruned["insert: " + insert.reason.substr(0, insert.reason.find(" at "))];
      continue;
    }
    const JointVector q_place = insert.waypoints.back();
    CollisionWorld w_after(w_carry);
    w_after.addObject(p.part.name, mesh, T_target_used);
    CollisionContext c_after{&w_after, open, nullptr, -1};
    const Eigen::Isometry3d T_retreat = T_place * alongZ(-assembly_.retreat_distance);
    const PathResult retreat = motion_.planCartesian(q_place, tool0(T_retreat), c_after);
    if (!retreat.ok) {
      ++p.pruned["retreat: " + retreat.reason.substr(0, retreat.reason.find(" at "))];
      continue;
    }
    const PathResult transfer = motion_.planJoint(q_lift, *q_pp, c_carry);
    if (!transfer.ok) {
      ++p.pruned["transfer: " + transfer.reason.substr(0, transfer.reason.find(" ("))];
      continue;
    }
    const PathResult to_pre = motion_.planJoint(start, *q_pre, c_open);
    if (!to_pre.ok) {
      ++p.pruned["to pre-grasp: " + to_pre.reason.substr(0, to_pre.reason.find(" ("))];
      continue;
    }
    // the plan
    p.grasp = g;
    p.grip_opening = g.width;
    p.T_base_target = T_target_used;
    p.sampled = to_pre.sampled || transfer.sampled;
    p.poses = {{"pre_grasp", T_pre, *q_pre},       {"grasp", T_grasp, q_grasp},
               {"lift", T_lift, q_lift},           {"pre_place", Eigen::Translation3d(-v * assembly_.preplace_distance) * T_place, *q_pp},
               {"place", T_place, q_place},        {"retreat", T_retreat, retreat.waypoints.back()}};
    p.segments = {{"to_pre_grasp", false, false, open, to_pre.waypoints}, {"approach", true, false, open, approach.waypoints},
                  {"lift", true, true, g.width, lift.waypoints},          {"transfer", false, true, g.width, transfer.waypoints},
                  {"insert", true, true, g.width, insert.waypoints},      {"retreat", true, false, open, retreat.waypoints}};
    TimedTrajectory traj;
    for (const PlanSegment& s : p.segments) {
      appendTrajectory(traj, s.cartesian ? motion_.timeSmoothPath(s.path) : motion_.timeJointPath(s.path));
      if (s.name == "approach") p.grasp_index = traj.positions.size() - 1;
      if (s.name == "insert") p.release_index = traj.positions.size() - 1;
    }
    p.trajectory = std::move(traj);
    return finish(PlanStatus::kOk, "");
  }
  std::string why;
  std::vector<std::pair<int, std::string>> counts;  // what the candidates that were planned ran into
  for (const auto& [r, n] : p.pruned) {
    if (!measured.count(r)) counts.emplace_back(n, r);
  }
  std::sort(counts.rbegin(), counts.rend());
  for (size_t i = 0; i < counts.size() && i < 4; ++i) why += (i ? "; " : "") + counts[i].second + " x" + std::to_string(counts[i].first);
  return finish(any_reachable ? PlanStatus::kNoPath : PlanStatus::kUnreachable,
                std::string(any_reachable ? "no collision-free plan" : "no grasp is reachable") + " (" +
                    std::to_string(p.candidates_tried) + " candidates tried: " + why + ")");
}

PartPlan GraspPlanner::planNext(const JointVector& start, size_t* index) const {
  PartPlan first_refusal;
  bool have_refusal = false;
  size_t refused = parts_.size();
  std::vector<std::string> passed_over;
  for (const std::string& model : assembly_.order) {
    for (size_t i = 0; i < parts_.size(); ++i) {
      if (parts_[i].model != model || placed_.count(i) || skipped_.count(i)) continue;
      PartPlan p = plan(i, start);
      if (p.status == PlanStatus::kOk) {
        if (index) *index = i;
        p.passed_over = passed_over;
        return p;
      }
      passed_over.push_back(parts_[i].name + ": " + planStatusName(p.status) + ": " + p.reason);
      if (!have_refusal) {
        first_refusal = p;
        have_refusal = true;
        refused = i;
      }
    }
  }
  if (index) *index = refused;
  first_refusal.passed_over = passed_over;
  if (!have_refusal) {
    first_refusal.status = PlanStatus::kNothingLeft;
    first_refusal.reason = "no part of the assembly is left to place";
  }
  return first_refusal;
}

void GraspPlanner::commit(size_t index, const PartPlan& plan) {
  if (index >= parts_.size() || plan.status != PlanStatus::kOk) throw std::invalid_argument("grasp planner: commit needs an ok plan of a located part");
  if (object_ids_[index] >= 0) world_->moveObject(object_ids_[index], plan.T_base_target);
  placed_[index] = 1;
}

}  // namespace cellsight
