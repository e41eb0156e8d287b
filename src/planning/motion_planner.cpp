#include "cellsight/planning/motion_planner.hpp"

#include <ompl/base/MotionValidator.h>
#include <ompl/base/spaces/RealVectorStateSpace.h>
#include <ompl/geometric/PathSimplifier.h>
#include <ompl/geometric/SimpleSetup.h>
#include <ompl/geometric/planners/prm/PRM.h>
#include <ompl/geometric/planners/rrt/RRT.h>
#include <ompl/geometric/planners/rrt/RRTConnect.h>
#include <ompl/util/Console.h>
#include <ompl/util/RandomNumbers.h>

#include <chrono>
#include <cmath>
#include <mutex>
#include <stdexcept>

namespace cellsight {

namespace ob = ompl::base;
namespace og = ompl::geometric;

namespace {

double now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

void quietOmpl() {
  static std::once_flag once;
  std::call_once(once, [] {
    ompl::msg::setLogLevel(ompl::msg::LOG_WARN);
    ompl::RNG::setSeed(1);  // reproducible plans (OMPL seeds once per process)
  });
}

/// OMPL's edges checked by MotionPlanner::edgeValid (the certified stepping), not OMPL's
/// fixed-resolution discrete validator.
class CertifiedMotionValidator : public ob::MotionValidator {
 public:
  CertifiedMotionValidator(const ob::SpaceInformationPtr& si, const MotionPlanner& mp, const CollisionContext& ctx)
      : ob::MotionValidator(si), mp_(mp), ctx_(ctx) {}
  bool checkMotion(const ob::State* s1, const ob::State* s2) const override {
    if (!si_->isValid(s2)) {
      ++invalid_;
      return false;
    }
    const bool ok = mp_.edgeValid(joints(s1), joints(s2), ctx_);
    ok ? ++valid_ : ++invalid_;
    return ok;
  }
  bool checkMotion(const ob::State* s1, const ob::State* s2, std::pair<ob::State*, double>& last_valid) const override {
    const JointVector a = joints(s1), b = joints(s2);
    const int n = mp_.certifiedSteps(a, b, ctx_);
    for (int i = 1; i <= n; ++i) {
      if (mp_.checkState(a + (b - a) * (static_cast<double>(i) / n), ctx_).collides) {
        const double t = static_cast<double>(i - 1) / n;
        if (last_valid.first) si_->getStateSpace()->interpolate(s1, s2, t, last_valid.first);
        last_valid.second = t;
        ++invalid_;
        return false;
      }
    }
    ++valid_;
    return true;
  }

 private:
  static JointVector joints(const ob::State* s) {
    const auto* v = s->as<ob::RealVectorStateSpace::StateType>();
    JointVector q;
    for (int i = 0; i < 6; ++i) q[i] = v->values[i];
    return q;
  }
  const MotionPlanner& mp_;
  CollisionContext ctx_;
};

PathResult finished(PathResult& out, double t0, bool ok, const std::string& reason) {
  out.ok = ok;
  out.reason = reason;
  out.seconds = now() - t0;
  return out;
}

}  // namespace

MotionPlanner::MotionPlanner(const ArmModel& arm, const MotionPlannerConfig& config) : arm_(arm), config_(config) {
  if (!(config_.edge_resolution > 0) || !(config_.cartesian_step > 0) || !(config_.planning_time > 0) ||
      !(config_.velocity_scale > 0 && config_.velocity_scale <= 1) || !(config_.acceleration > 0) ||
      !(config_.max_joint_jump > 0)) {
    throw std::invalid_argument(
        "motion planner: edge_resolution, cartesian_step, planning_time, acceleration, max_joint_jump > 0 and "
        "velocity_scale in (0, 1] required");
  }
  if (config_.planner != "rrtconnect" && config_.planner != "rrt" && config_.planner != "prm" && config_.planner != "straight") {
    throw std::invalid_argument("motion planner: planner '" + config_.planner + "' unknown (rrtconnect, rrt, prm, straight)");
  }
  quietOmpl();
}

CollisionReport MotionPlanner::checkState(const JointVector& q, const CollisionContext& ctx) const {
  if (!arm_.withinLimits(q)) {
    CollisionReport r;
    r.collides = true;
    r.first = "joints";
    r.second = "limits";
    return r;
  }
  if (!ctx.world) return {};
  return ctx.world->check(arm_, q, ctx.opening, ctx.carried, ctx.ignore_object);
}

int MotionPlanner::certifiedSteps(const JointVector& a, const JointVector& b, const CollisionContext& ctx) const {
  const double padding = ctx.world ? ctx.world->config().padding : 0.0;
  double sweep = 0;  // upper bound of any point's travel along the edge
  for (int j = 0; j < 6; ++j) sweep += std::abs(b[j] - a[j]) * config_.reach[static_cast<size_t>(j)];
  const int by_padding = padding > 0 ? static_cast<int>(std::ceil(sweep / padding)) : 1;
  const int by_angle = static_cast<int>(std::ceil(jointDistance(a, b) / config_.edge_resolution));
  return std::max({1, by_padding, by_angle});
}

bool MotionPlanner::edgeValid(const JointVector& a, const JointVector& b, const CollisionContext& ctx,
                              double resolution, CollisionReport* where) const {
  if (resolution <= 0 && ctx.world && ctx.world->config().padding > 0) {
    // conservative advancement: from each free state, every point may travel the clearance
    // there plus the padding before the next check (travel bound: Σ |Δq_j| · reach_j per unit s)
    double rate = 0;
    for (int j = 0; j < 6; ++j) rate += std::abs(b[j] - a[j]) * config_.reach[static_cast<size_t>(j)];
    const double padding = ctx.world->config().padding;
    const double max_ds = jointDistance(a, b) > 0 ? config_.edge_resolution / jointDistance(a, b) : 1.0;
    double s = 0;
    while (true) {
      const CollisionReport r = checkState(a + (b - a) * s, ctx);
      if (r.collides) {
        if (where) *where = r;
        return false;
      }
      if (s >= 1 || rate <= 0) return true;
      s = std::min(1.0, s + std::min(max_ds, (r.clearance + padding) / rate));
    }
  }
  const int n = resolution > 0 ? std::max(1, static_cast<int>(std::ceil(jointDistance(a, b) / resolution)))
                               : certifiedSteps(a, b, ctx);
  for (int i = 0; i <= n; ++i) {
    const JointVector q = a + (b - a) * (static_cast<double>(i) / n);
    const CollisionReport r = checkState(q, ctx);
    if (r.collides) {
      if (where) *where = r;
      return false;
    }
  }
  return true;
}

bool MotionPlanner::pathValid(const std::vector<JointVector>& path, const CollisionContext& ctx, double resolution,
                              CollisionReport* where) const {
  if (path.empty()) return false;
  if (path.size() == 1) {
    const CollisionReport r = checkState(path[0], ctx);
    if (where) *where = r;
    return !r.collides;
  }
  for (size_t i = 0; i + 1 < path.size(); ++i) {
    if (!edgeValid(path[i], path[i + 1], ctx, resolution, where)) return false;
  }
  return true;
}

PathResult MotionPlanner::planJoint(const JointVector& from, const JointVector& to, const CollisionContext& ctx) const {
  const double t0 = now();
  PathResult out;
  auto done = [&](bool ok, const std::string& reason) { return finished(out, t0, ok, reason); };
  CollisionReport r = checkState(from, ctx);
  if (r.collides) return done(false, "the start collides: " + r.text());
  r = checkState(to, ctx);
  if (r.collides) return done(false, "the goal collides: " + r.text());
  if ((config_.direct_first || config_.planner == "straight") && edgeValid(from, to, ctx, 0, &r)) {
    out.waypoints = {from, to};
    return done(true, "");
  }
  if (config_.planner == "straight") return done(false, "the straight joint edge collides: " + r.text());
  out.sampled = true;
  auto space = std::make_shared<ob::RealVectorStateSpace>(6);
  ob::RealVectorBounds bounds(6);
  for (int i = 0; i < 6; ++i) {
    bounds.setLow(i, arm_.lower()[i]);
    bounds.setHigh(i, arm_.upper()[i]);
  }
  space->setBounds(bounds);
  og::SimpleSetup ss(space);
  ss.setStateValidityChecker([&](const ob::State* s) {
    const auto* v = s->as<ob::RealVectorStateSpace::StateType>();
    JointVector q;
    for (int i = 0; i < 6; ++i) q[i] = v->values[i];
    return !checkState(q, ctx).collides;
  });
  const auto si = ss.getSpaceInformation();
  si->setMotionValidator(std::make_shared<CertifiedMotionValidator>(si, *this, ctx));
  if (config_.planner == "rrt") {
    ss.setPlanner(std::make_shared<og::RRT>(si));
  } else if (config_.planner == "prm") {
    ss.setPlanner(std::make_shared<og::PRM>(si));
  } else {
    ss.setPlanner(std::make_shared<og::RRTConnect>(si));
  }
  ob::ScopedState<> start(space), goal(space);
  for (int i = 0; i < 6; ++i) {
    start[i] = from[i];
    goal[i] = to[i];
  }
  ss.setStartAndGoalStates(start, goal);
  const ob::PlannerStatus st = ss.solve(config_.planning_time);
  if (st != ob::PlannerStatus::EXACT_SOLUTION) {
    return done(false, std::string("no collision-free joint path within ") + std::to_string(config_.planning_time) +
                           " s (" + st.asString() + ")");
  }
  og::PathGeometric& path = ss.getSolutionPath();
  if (config_.simplify) {
    // vertices dropped where a straight joint edge is free (each try is one certified edge
    // check), then shortcuts, within simplify_time
    og::PathSimplifier ps(si);
    const double t_end = now() + config_.simplify_time;
    const ob::PlannerTerminationCondition ptc([&] { return now() > t_end; });
    ps.reduceVertices(path);
    if (!ptc) ps.shortcutPath(path, 0, 0, 0.33, 0.005);
    ps.reduceVertices(path);
  }
  for (std::size_t i = 0; i < path.getStateCount(); ++i) {
    const auto* v = path.getState(i)->as<ob::RealVectorStateSpace::StateType>();
    JointVector q;
    for (int k = 0; k < 6; ++k) q[k] = v->values[k];
    out.waypoints.push_back(q);
  }
  // every edge of it passed the certified check (OMPL's motion validator is ours)
  return done(true, "");
}

PathResult MotionPlanner::planCartesian(const JointVector& from, const Eigen::Isometry3d& target,
                                        const CollisionContext& ctx) const {
  const double t0 = now();
  PathResult out;
  auto done = [&](bool ok, const std::string& reason) { return finished(out, t0, ok, reason); };
  const Eigen::Isometry3d start = arm_.fk(from);
  const Eigen::Quaterniond qa(start.linear()), qb(target.linear());
  const double dist = (target.translation() - start.translation()).norm();
  const double ang = qa.angularDistance(qb);
  const int n = std::max(1, static_cast<int>(std::ceil(std::max(dist / config_.cartesian_step, ang / (config_.cartesian_step / 0.05)))));
  out.waypoints.push_back(from);
  JointVector prev = from;
  CollisionReport r = checkState(from, ctx);
  if (r.collides) return done(false, "the start collides: " + r.text());
  for (int i = 1; i <= n; ++i) {
    const double s = static_cast<double>(i) / n;
    Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
    T.linear() = qa.slerp(s, qb).toRotationMatrix();
    T.translation() = start.translation() + s * (target.translation() - start.translation());
    IkConfig ik;
    ik.max_seeds = 0;  // continue the seed's branch only
    const auto q = arm_.ik(T, prev, ik);
    if (!q) return done(false, "straight line leaves the reachable space at " + std::to_string(static_cast<int>(s * 100)) + " %");
    if (jointDistance(*q, prev) > config_.max_joint_jump) {
      return done(false, "straight line needs a joint jump (" + std::to_string(jointDistance(*q, prev)) + " rad) at " +
                             std::to_string(static_cast<int>(s * 100)) + " %");
    }
    if (!edgeValid(prev, *q, ctx, 0, &r)) return done(false, "straight line collides: " + r.text());
    out.waypoints.push_back(*q);
    prev = *q;
  }
  return done(true, "");
}

namespace {

/// Time for a rest-to-rest trapezoid over `d` with speed v and acceleration a.
double trapezoidTime(double d, double v, double a) {
  if (d <= 0) return 0;
  if (d >= v * v / a) return d / v + v / a;
  return 2 * std::sqrt(d / a);
}

/// Position share s(t)/d and speed of that trapezoid at t (total T).
void trapezoidAt(double d, double v, double a, double t, double* s, double* sd) {
  const double T = trapezoidTime(d, v, a);
  if (d <= 0 || T <= 0) {
    *s = 1;
    *sd = 0;
    return;
  }
  const double vp = std::min(v, std::sqrt(d * a));  // peak speed
  const double ta = vp / a;
  double pos, vel;
  if (t < ta) {
    pos = 0.5 * a * t * t;
    vel = a * t;
  } else if (t < T - ta) {
    pos = 0.5 * a * ta * ta + vp * (t - ta);
    vel = vp;
  } else {
    const double tr = std::max(0.0, T - t);
    pos = d - 0.5 * a * tr * tr;
    vel = a * tr;
  }
  *s = pos / d;
  *sd = vel / d;
}

}  // namespace

TimedTrajectory MotionPlanner::timeJointPath(const std::vector<JointVector>& path) const {
  TimedTrajectory out;
  if (path.empty()) return out;
  out.positions.push_back(path[0]);
  out.velocities.push_back(JointVector::Zero());
  out.times.push_back(0);
  const JointVector vmax = arm_.maxVelocity() * config_.velocity_scale;
  const double dt = 0.02;
  for (size_t i = 0; i + 1 < path.size(); ++i) {
    const JointVector delta = path[i + 1] - path[i];
    // the slowest joint sets the edge's time; every joint follows the same normalised profile
    double T = 0;
    int slow = 0;
    for (int j = 0; j < 6; ++j) {
      const double tj = trapezoidTime(std::abs(delta[j]), vmax[j], config_.acceleration);
      if (tj > T) {
        T = tj;
        slow = j;
      }
    }
    const double t_start = out.times.back();
    if (T <= 0) continue;
    const double d = std::abs(delta[slow]);
    const int steps = std::max(1, static_cast<int>(std::ceil(T / dt)));
    for (int k = 1; k <= steps; ++k) {
      const double t = T * k / steps;
      double s, sd;
      trapezoidAt(d, vmax[slow], config_.acceleration, t, &s, &sd);
      out.positions.push_back(path[i] + delta * s);
      out.velocities.push_back(delta * sd);
      out.times.push_back(t_start + t);
    }
  }
  return out;
}

TimedTrajectory MotionPlanner::timeSmoothPath(const std::vector<JointVector>& path) const {
  TimedTrajectory out;
  if (path.empty()) return out;
  // arc length in the max-norm: every joint moves at most ds per unit s
  std::vector<double> s(path.size(), 0.0);
  for (size_t i = 1; i < path.size(); ++i) s[i] = s[i - 1] + jointDistance(path[i], path[i - 1]);
  const double L = s.back();
  const double v = arm_.maxVelocity().minCoeff() * config_.velocity_scale;
  const double a = config_.acceleration;
  const double T = trapezoidTime(L, v, a);
  for (size_t i = 0; i < path.size(); ++i) {
    // invert s(t) for this waypoint by bisection on the monotone profile
    double lo = 0, hi = T;
    for (int it = 0; it < 50 && L > 0; ++it) {
      const double mid = 0.5 * (lo + hi);
      double sh, sd;
      trapezoidAt(L, v, a, mid, &sh, &sd);
      (sh * L < s[i] ? lo : hi) = mid;
    }
    const double t = L > 0 ? 0.5 * (lo + hi) : 0.0;
    double sh = 0, sd = 0;
    if (L > 0) trapezoidAt(L, v, a, t, &sh, &sd);
    JointVector dir = JointVector::Zero();
    if (i + 1 < path.size() && s[i + 1] > s[i]) dir = (path[i + 1] - path[i]) / (s[i + 1] - s[i]);
    else if (i > 0 && s[i] > s[i - 1]) dir = (path[i] - path[i - 1]) / (s[i] - s[i - 1]);
    out.positions.push_back(path[i]);
    out.velocities.push_back(dir * (sd * L));
    out.times.push_back(t);
  }
  return out;
}

void appendTrajectory(TimedTrajectory& a, const TimedTrajectory& b) {
  if (b.positions.empty()) return;
  const double t0 = a.times.empty() ? 0.0 : a.times.back();
  size_t first = 0;
  double shift = t0;
  if (!a.positions.empty()) {
    if (jointDistance(a.positions.back(), b.positions.front()) < 1e-9) first = 1;
    else shift += 1e-3;  // two distinct points never share a time
  }
  for (size_t i = first; i < b.positions.size(); ++i) {
    a.positions.push_back(b.positions[i]);
    a.velocities.push_back(b.velocities[i]);
    a.times.push_back(shift + b.times[i]);
  }
}

}  // namespace cellsight
