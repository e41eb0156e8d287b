#include "cellsight/sim/robot_model.hpp"

#include "cellsight/common/kdl_eigen.hpp"

#include <kdl/chain.hpp>
#include <kdl/chainfksolverpos_recursive.hpp>
#include <kdl/chainiksolverpos_lma.hpp>

#include <algorithm>
#include <cmath>
#include <mutex>
#include <random>
#include <stdexcept>
#include <vector>

namespace cellsight {

namespace {

constexpr double kDeg = M_PI / 180.0;

KDL::Chain chainOf(const std::array<DhRow, 6>& dh) {
  KDL::Chain c;
  for (const DhRow& r : dh) {
    // standard DH: RotZ(q + theta) Trans_z(d) Trans_x(a) RotX(alpha); the offset goes into the
    // fixed part as a rotation about z ahead of the rest (RotZ(q) RotZ(theta) ...).
    c.addSegment(KDL::Segment(KDL::Joint(KDL::Joint::RotZ), KDL::Frame::DH(r.a, r.alpha, r.d, r.theta)));
  }
  return c;
}

uint64_t mix(uint64_t x) {
  x += 0x9E3779B97F4A7C15ull;
  x = (x ^ (x >> 30)) * 0xBF58476D1CE4E5B9ull;
  x = (x ^ (x >> 27)) * 0x94D049BB133111EBull;
  return x ^ (x >> 31);
}

}  // namespace

struct RobotErrorModel::Kdl {
  KDL::Chain nominal, built;
  KDL::ChainFkSolverPos_recursive fk_nominal, fk_built;
  KDL::ChainIkSolverPos_LMA ik;  // keeps state between calls: used under `mutex`
  std::mutex mutex;
  std::vector<KDL::JntArray> seeds;
  Kdl(const std::array<DhRow, 6>& n, const std::array<DhRow, 6>& b)
      : nominal(chainOf(n)), built(chainOf(b)), fk_nominal(nominal), fk_built(built),
        ik(nominal, Eigen::Matrix<double, 6, 1>::Ones(), 1e-12, 500, 1e-15) {}
};

std::array<DhRow, 6> RobotErrorModel::nominalDh() {
  // A 6-kg-class arm with a spherical wrist (KR 6 R900-like; reach 0.9 m), base at base_link.
  return {{{0.025, -M_PI / 2, 0.400, 0.0},
           {0.455, 0.0, 0.0, -M_PI / 2},
           {0.035, -M_PI / 2, 0.0, 0.0},
           {0.0, M_PI / 2, 0.420, 0.0},
           {0.0, -M_PI / 2, 0.0, 0.0},
           {0.0, 0.0, 0.080, 0.0}}};
}

RobotErrorModel::RobotErrorModel(const RobotErrorConfig& config) : config_(config) {
  const auto nominal = nominalDh();
  built_ = nominal;
  if (!config_.enabled) return;
  if (!(config_.joint_offset_deg >= 0 && config_.link_mm >= 0 && config_.twist_deg >= 0 &&
        config_.repeatability_mm >= 0 && config_.repeatability_deg >= 0)) {
    throw std::invalid_argument("robot error model: every sigma must be >= 0");
  }
  std::mt19937_64 rng(mix(config_.seed));
  std::normal_distribution<double> n01(0.0, 1.0);
  for (DhRow& r : built_) {
    r.a += config_.link_mm * 1e-3 * n01(rng);
    r.d += config_.link_mm * 1e-3 * n01(rng);
    r.alpha += config_.twist_deg * kDeg * n01(rng);
    r.theta += config_.joint_offset_deg * kDeg * n01(rng);
  }
  kdl_ = std::make_unique<Kdl>(nominal, built_);
  // Seeds: elbow-up, wrist-down configurations (the pose (0.5, 0, 0.3) pointing down and a few
  // rotated about the base); the closest converged one wins per pose.
  for (double q1 : {0.0, 0.8, -0.8, 1.6, -1.6}) {
    KDL::JntArray q(6);
    const double v[6] = {q1, -0.35, 0.65, 0.0, 1.27, 0.0};
    for (int i = 0; i < 6; ++i) q(i) = v[i];
    kdl_->seeds.push_back(q);
  }
}

RobotErrorModel::~RobotErrorModel() = default;
RobotErrorModel::RobotErrorModel(RobotErrorModel&&) noexcept = default;
RobotErrorModel& RobotErrorModel::operator=(RobotErrorModel&&) noexcept = default;

Eigen::Isometry3d RobotErrorModel::actualSystematic(const Eigen::Isometry3d& commanded) const {
  if (!config_.enabled) return commanded;
  const KDL::Frame target = toKdl(commanded);
  // The seed nearest in base yaw first: the solution stays on one branch across a scan.
  const double yaw = std::atan2(commanded.translation().y(), commanded.translation().x());
  std::vector<const KDL::JntArray*> order;
  for (const auto& s : kdl_->seeds) order.push_back(&s);
  std::sort(order.begin(), order.end(),
            [&](const KDL::JntArray* a, const KDL::JntArray* b) { return std::abs((*a)(0) - yaw) < std::abs((*b)(0) - yaw); });
  std::lock_guard<std::mutex> lock(kdl_->mutex);
  for (const KDL::JntArray* seed : order) {
    KDL::JntArray init = *seed;
    init(0) = yaw;
    KDL::JntArray q(6);
    // the return code may say "increments too small" near the wrist singularity of a flange
    // pointing straight down although the pose is reached: check the pose itself
    kdl_->ik.CartToJnt(init, target, q);
    KDL::Frame check;
    kdl_->fk_nominal.JntToCart(q, check);
    if ((check.p - target.p).Norm() > 1e-8 || !KDL::Equal(check.M, target.M, 1e-6)) continue;
    KDL::Frame built;
    kdl_->fk_built.JntToCart(q, built);
    return fromKdl(built);
  }
  throw std::runtime_error("robot error model: the arm cannot reach the commanded flange pose (" +
                           std::to_string(commanded.translation().x()) + ", " +
                           std::to_string(commanded.translation().y()) + ", " +
                           std::to_string(commanded.translation().z()) + ")");
}

Eigen::Isometry3d RobotErrorModel::nominalAtJoints(const Eigen::Matrix<double, 6, 1>& q) const {
  KDL::JntArray jq(6);
  jq.data = q;
  KDL::Frame F;
  if (kdl_) {
    std::lock_guard<std::mutex> lock(kdl_->mutex);
    kdl_->fk_nominal.JntToCart(jq, F);
  } else {
    const KDL::Chain c = chainOf(nominalDh());
    KDL::ChainFkSolverPos_recursive(c).JntToCart(jq, F);
  }
  return fromKdl(F);
}

Eigen::Isometry3d RobotErrorModel::actualAtJoints(const Eigen::Matrix<double, 6, 1>& q, uint64_t move) const {
  if (!config_.enabled) return nominalAtJoints(q);
  KDL::JntArray jq(6);
  jq.data = q;
  KDL::Frame F;
  {
    std::lock_guard<std::mutex> lock(kdl_->mutex);
    kdl_->fk_built.JntToCart(jq, F);
  }
  return withScatter(fromKdl(F), move);
}

Eigen::Isometry3d RobotErrorModel::withScatter(Eigen::Isometry3d T, uint64_t move) const {
  std::mt19937_64 rng(mix(config_.seed ^ mix(move + 0x5151)));
  std::normal_distribution<double> n01(0.0, 1.0);
  const Eigen::Vector3d dp(n01(rng), n01(rng), n01(rng));
  const Eigen::Vector3d dr(n01(rng), n01(rng), n01(rng));
  T.translation() += dp * config_.repeatability_mm * 1e-3;
  const Eigen::Vector3d w = dr * config_.repeatability_deg * kDeg;
  if (w.norm() > 0) T.linear() = Eigen::AngleAxisd(w.norm(), w.normalized()).toRotationMatrix() * T.linear();
  return T;
}

Eigen::Isometry3d RobotErrorModel::actual(const Eigen::Isometry3d& commanded, uint64_t move) const {
  if (!config_.enabled) return commanded;
  return withScatter(actualSystematic(commanded), move);
}

Eigen::Isometry3d RobotErrorModel::reported(const Eigen::Isometry3d& actual_pose) const {
  if (!config_.enabled) return actual_pose;
  Eigen::Isometry3d r = actual_pose;
  for (int i = 0; i < 6; ++i) {
    const Eigen::Isometry3d e = actualSystematic(r);
    r = actual_pose * e.inverse() * r;
  }
  return r;
}

}  // namespace cellsight
