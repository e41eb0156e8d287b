#include "cellsight/planning/arm_model.hpp"

#include <kdl/chain.hpp>
#include <kdl/chainfksolverpos_recursive.hpp>
#include <kdl/chainjnttojacsolver.hpp>
#include <kdl/tree.hpp>
#include <kdl_parser/kdl_parser.hpp>
#include <urdf_parser/urdf_parser.h>

#include <cmath>
#include <fstream>
#include <map>
#include <sstream>

#include "cellsight/common/errors.hpp"
#include "cellsight/common/kdl_eigen.hpp"

namespace cellsight {

namespace {

Eigen::Isometry3d fromUrdf(const urdf::Pose& p) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(p.position.x, p.position.y, p.position.z);
  T.linear() = Eigen::Quaterniond(p.rotation.w, p.rotation.x, p.rotation.y, p.rotation.z).normalized().toRotationMatrix();
  return T;
}

}  // namespace

struct ArmModel::Kdl {
  KDL::Chain chain;
  KDL::ChainFkSolverPos_recursive fk;
  KDL::ChainJntToJacSolver jac;
  explicit Kdl(const KDL::Chain& c) : chain(c), fk(chain), jac(chain) {}
  /// Damped least squares (Levenberg–Marquardt on the 6-D pose error, KDL's Jacobian at the tool):
  /// Debian's KDL::ChainIkSolverPos_LMA trips an Eigen assertion on some seeds, so the iteration is ours.
  bool solve(const KDL::JntArray& seed, const KDL::Frame& target, KDL::JntArray& q, double tol_p, double tol_r) {
    q = seed;
    double lambda = 1e-3;
    KDL::Frame F;
    KDL::Jacobian J(6);
    auto error = [&](const KDL::Frame& f) {
      const KDL::Twist d = KDL::diff(f, target);  // in the base frame
      Eigen::Matrix<double, 6, 1> e;
      e << d.vel.x(), d.vel.y(), d.vel.z(), d.rot.x(), d.rot.y(), d.rot.z();
      return e;
    };
    fk.JntToCart(q, F);
    Eigen::Matrix<double, 6, 1> e = error(F);
    for (int it = 0; it < 200; ++it) {
      if (e.head<3>().norm() < tol_p && e.tail<3>().norm() < tol_r) return true;
      jac.JntToJac(q, J);
      const Eigen::Matrix<double, 6, 6> A = J.data * J.data.transpose() + lambda * lambda * Eigen::Matrix<double, 6, 6>::Identity();
      Eigen::Matrix<double, 6, 1> dq = J.data.transpose() * A.ldlt().solve(e);
      const double m = dq.cwiseAbs().maxCoeff();
      if (m > 0.3) dq *= 0.3 / m;
      KDL::JntArray qn(6);
      qn.data = q.data + dq;
      KDL::Frame Fn;
      fk.JntToCart(qn, Fn);
      const Eigen::Matrix<double, 6, 1> en = error(Fn);
      if (en.norm() < e.norm()) {
        q = qn;
        e = en;
        lambda = std::max(1e-6, lambda * 0.3);
      } else {
        lambda *= 10;
        if (lambda > 1e3) return false;
      }
    }
    return e.head<3>().norm() < tol_p && e.tail<3>().norm() < tol_r;
  }
};

ArmModel::ArmModel() = default;
ArmModel::ArmModel(ArmModel&&) noexcept = default;
ArmModel& ArmModel::operator=(ArmModel&&) noexcept = default;
ArmModel::~ArmModel() = default;
ArmModel::ArmModel(const ArmModel& o)
    : joint_names_(o.joint_names_), lower_(o.lower_), upper_(o.upper_), max_velocity_(o.max_velocity_),
      tool0_tcp_(o.tool0_tcp_), max_opening_(o.max_opening_), shapes_(o.shapes_),
      kdl_(std::make_unique<Kdl>(o.kdl_->chain)) {}

ArmModel ArmModel::fromUrdfFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw ConfigError(path + ": cannot read the robot description (URDF)");
  std::stringstream ss;
  ss << in.rdbuf();
  return fromUrdfString(ss.str(), path);
}

ArmModel ArmModel::fromUrdfString(const std::string& xml, const std::string& source) {
  const urdf::ModelInterfaceSharedPtr model = urdf::parseURDF(xml);
  if (!model) throw ConfigError(source + ": not a valid URDF (urdfdom could not parse it)");
  for (const char* name : {"base_link", "tool0", "tcp"}) {
    if (!model->getLink(name)) throw ConfigError(source + ": the URDF has no link '" + name + "'");
  }
  KDL::Tree tree;
  if (!kdl_parser::treeFromUrdfModel(*model, tree)) throw ConfigError(source + ": kdl_parser could not build a tree");
  KDL::Chain chain;
  if (!tree.getChain("base_link", "tool0", chain)) throw ConfigError(source + ": no chain base_link -> tool0");
  if (chain.getNrOfJoints() != 6) {
    throw ConfigError(source + ": the chain base_link -> tool0 has " + std::to_string(chain.getNrOfJoints()) +
                      " movable joints, 6 expected");
  }
  ArmModel arm;
  std::map<std::string, int> chain_frame;  // link name → chain frame index
  chain_frame["base_link"] = 0;
  int j = 0;
  for (unsigned s = 0; s < chain.getNrOfSegments(); ++s) {
    const KDL::Segment& seg = chain.getSegment(s);
    chain_frame[seg.getName()] = static_cast<int>(s) + 1;
    if (seg.getJoint().getType() == KDL::Joint::None) continue;
    const std::string jn = seg.getJoint().getName();
    const urdf::JointConstSharedPtr uj = model->getJoint(jn);
    if (!uj || !uj->limits) throw ConfigError(source + ": joint '" + jn + "' has no <limit>");
    arm.joint_names_[j] = jn;
    arm.lower_[j] = uj->limits->lower;
    arm.upper_[j] = uj->limits->upper;
    arm.max_velocity_[j] = uj->limits->velocity;
    if (!(arm.lower_[j] < arm.upper_[j]) || !(arm.max_velocity_[j] > 0)) {
      throw ConfigError(source + ": joint '" + jn + "': lower < upper and velocity > 0 required");
    }
    ++j;
  }
  arm.kdl_ = std::make_unique<Kdl>(chain);
  // every link hangs from a chain link through fixed or prismatic joints
  std::vector<urdf::LinkSharedPtr> links;
  model->getLinks(links);
  for (const auto& link : links) {
    Eigen::Isometry3d in_chain = Eigen::Isometry3d::Identity();
    Eigen::Vector3d slide = Eigen::Vector3d::Zero();
    urdf::LinkConstSharedPtr l = link;
    bool prismatic = false;
    double travel = 0;
    while (l && !chain_frame.count(l->name)) {
      const urdf::JointConstSharedPtr pj = l->parent_joint;
      if (!pj) break;
      const Eigen::Isometry3d o = fromUrdf(pj->parent_to_joint_origin_transform);
      if (pj->type == urdf::Joint::PRISMATIC) {
        if (l != link || prismatic) {
          throw ConfigError(source + ": link '" + link->name + "': a prismatic joint is only supported as a finger's own joint");
        }
        prismatic = true;
        slide = Eigen::Vector3d(pj->axis.x, pj->axis.y, pj->axis.z).normalized();
        travel = pj->limits ? pj->limits->upper : 0;
      } else if (pj->type != urdf::Joint::FIXED) {
        throw ConfigError(source + ": link '" + link->name + "' hangs from the chain through the movable joint '" +
                          pj->name + "'");
      }
      in_chain = o * in_chain;
      l = model->getLink(pj->parent_link_name);
    }
    if (!l || !chain_frame.count(l->name)) continue;  // e.g. a world link above base_link: not the arm's
    const int frame = chain_frame.at(l->name);
    if (link->name == "tcp") {
      if (frame != chain_frame.at("tool0")) throw ConfigError(source + ": link 'tcp' must hang from tool0");
      arm.tool0_tcp_ = in_chain;
    }
    if (prismatic) arm.max_opening_ += travel;
    for (const auto& c : link->collision_array) {
      if (!c || !c->geometry) continue;
      CollisionShape s;
      s.link = link->name;
      s.chain_index = frame;
      s.in_chain = in_chain;
      s.origin = fromUrdf(c->origin);
      if (prismatic) {
        s.finger = true;
        s.slide_axis = slide;
      }
      switch (c->geometry->type) {
        case urdf::Geometry::BOX: {
          const auto* b = static_cast<const urdf::Box*>(c->geometry.get());
          s.type = CollisionShape::Type::kBox;
          s.size = Eigen::Vector3d(b->dim.x, b->dim.y, b->dim.z);
          break;
        }
        case urdf::Geometry::CYLINDER: {
          const auto* cy = static_cast<const urdf::Cylinder*>(c->geometry.get());
          s.type = CollisionShape::Type::kCylinder;
          s.size = Eigen::Vector3d(cy->radius, cy->length, 0);
          break;
        }
        case urdf::Geometry::SPHERE: {
          const auto* sp = static_cast<const urdf::Sphere*>(c->geometry.get());
          s.type = CollisionShape::Type::kSphere;
          s.size = Eigen::Vector3d(sp->radius, 0, 0);
          break;
        }
        default:
          throw ConfigError(source + ": link '" + link->name + "': only box, cylinder and sphere collision shapes");
      }
      arm.shapes_.push_back(s);
    }
  }
  if (arm.max_opening_ <= 0) throw ConfigError(source + ": no prismatic finger joints with an upper limit");
  return arm;
}

bool ArmModel::withinLimits(const JointVector& q, double margin) const {
  for (int i = 0; i < 6; ++i) {
    if (!std::isfinite(q[i]) || q[i] < lower_[i] + margin || q[i] > upper_[i] - margin) return false;
  }
  return true;
}

Eigen::Isometry3d ArmModel::fk(const JointVector& q) const {
  KDL::JntArray jq(6);
  jq.data = q;
  KDL::Frame F;
  kdl_->fk.JntToCart(jq, F);
  return fromKdl(F);
}

Isometries ArmModel::chainFrames(const JointVector& q) const {
  KDL::JntArray jq(6);
  jq.data = q;
  const unsigned n = kdl_->chain.getNrOfSegments();
  Isometries out(n + 1, Eigen::Isometry3d::Identity());
  // one pass: accumulate segment poses
  KDL::Frame F = KDL::Frame::Identity();
  int j = 0;
  for (unsigned s = 0; s < n; ++s) {
    const KDL::Segment& seg = kdl_->chain.getSegment(s);
    const double qs = seg.getJoint().getType() == KDL::Joint::None ? 0.0 : q[j++];
    F = F * seg.pose(qs);
    out[s + 1] = fromKdl(F);
  }
  return out;
}

Isometries ArmModel::shapePoses(const JointVector& q, double opening) const {
  const Isometries frames = chainFrames(q);
  Isometries out;
  out.reserve(shapes_.size());
  for (const CollisionShape& s : shapes_) {
    Eigen::Isometry3d T = frames[static_cast<size_t>(s.chain_index)] * s.in_chain;
    if (s.finger) T = T * Eigen::Translation3d(s.slide_axis * (0.5 * opening));
    out.push_back(T * s.origin);
  }
  return out;
}

std::optional<JointVector> ArmModel::ik(const Eigen::Isometry3d& T_base_tool0, const JointVector& seed,
                                        const IkConfig& config) const {
  if (!T_base_tool0.matrix().allFinite() || !seed.allFinite()) return std::nullopt;
  const KDL::Frame target = toKdl(T_base_tool0);
  // branch seeds: shoulder front/back, elbow up/down, wrist flipped, centred in the limits
  std::vector<JointVector> seeds{seed};
  const double pi = M_PI;
  for (double s1 : {0.0, pi}) {
    for (double e : {0.0, 1.0}) {
      for (double w : {0.0, 1.0}) {
        JointVector q;
        const double a1 = std::atan2(T_base_tool0.translation().y(), T_base_tool0.translation().x()) + s1;
        q << std::remainder(a1, 2 * pi), e ? -0.3 : -1.2, e ? 0.3 : 1.6, w ? pi / 2 : 0.0, w ? -1.0 : 1.0, 0.0;
        seeds.push_back(q);
      }
    }
  }
  std::optional<JointVector> best;
  double best_d = 1e300;
  const int n_seeds = std::min<int>(static_cast<int>(seeds.size()), std::max(1, config.max_seeds + 1));
  for (int k = 0; k < n_seeds; ++k) {
    KDL::JntArray q0(6), q(6);
    q0.data = seeds[static_cast<size_t>(k)];
    if (!kdl_->solve(q0, target, q, config.position_tolerance * 0.1, config.rotation_tolerance * 0.1)) continue;
    JointVector sol = q.data;
    // each joint to the 2π-equivalent nearest the seed, inside the limits
    bool ok = true;
    for (int i = 0; i < 6; ++i) {
      double v = sol[i];
      v = seed[i] + std::remainder(v - seed[i], 2 * pi);
      if (v < lower_[i]) v += 2 * pi;
      if (v > upper_[i]) v -= 2 * pi;
      if (v < lower_[i] || v > upper_[i]) { ok = false; break; }
      sol[i] = v;
    }
    if (!ok) continue;
    const Eigen::Isometry3d got = fk(sol);
    const double dp = (got.translation() - T_base_tool0.translation()).norm();
    const double dr = Eigen::AngleAxisd(got.linear().transpose() * T_base_tool0.linear()).angle();
    if (dp > config.position_tolerance || dr > config.rotation_tolerance) continue;
    const double d = jointDistance(sol, seed);
    if (d < best_d) {
      best_d = d;
      best = sol;
    }
    if (k == 0 && d < 0.5) break;  // the seed's own branch, near it: the continuation wanted
  }
  return best;
}

}  // namespace cellsight
