#include "cellsight/scanner/accuracy.hpp"

#include <Eigen/Dense>
#include <algorithm>
#include <cmath>

namespace cellsight {

SphereFit fitSphere(const std::vector<Eigen::Vector3d>& pts, double fixed_radius) {
  SphereFit f;
  f.points = pts.size();
  if (pts.size() < 4) return f;
  // Algebraic: |p|² = 2 c·p + (r² − |c|²), linear in (c, k).
  Eigen::MatrixXd A(pts.size(), 4);
  Eigen::VectorXd b(pts.size());
  const Eigen::Vector3d mean = [&] {
    Eigen::Vector3d m = Eigen::Vector3d::Zero();
    for (const auto& p : pts) m += p;
    return Eigen::Vector3d(m / static_cast<double>(pts.size()));
  }();
  for (size_t i = 0; i < pts.size(); ++i) {
    const Eigen::Vector3d q = pts[i] - mean;  // centred for conditioning
    A.row(static_cast<Eigen::Index>(i)) << 2 * q.x(), 2 * q.y(), 2 * q.z(), 1.0;
    b(static_cast<Eigen::Index>(i)) = q.squaredNorm();
  }
  const Eigen::Vector4d x = A.colPivHouseholderQr().solve(b);
  Eigen::Vector3d c = x.head<3>();
  double r = std::sqrt(std::max(1e-12, x(3) + c.squaredNorm()));
  if (fixed_radius > 0) r = fixed_radius;
  // Geometric refinement (Gauss–Newton on e_i = ‖q_i − c‖ − r).
  for (int it = 0; it < 50; ++it) {
    const int nparam = fixed_radius > 0 ? 3 : 4;
    Eigen::MatrixXd J(pts.size(), nparam);
    Eigen::VectorXd e(pts.size());
    for (size_t i = 0; i < pts.size(); ++i) {
      const Eigen::Vector3d q = pts[i] - mean - c;
      const double dist = std::max(1e-12, q.norm());
      e(static_cast<Eigen::Index>(i)) = dist - r;
      J.block<1, 3>(static_cast<Eigen::Index>(i), 0) = -q.transpose() / dist;
      if (nparam == 4) J(static_cast<Eigen::Index>(i), 3) = -1.0;
    }
    const Eigen::VectorXd step = J.colPivHouseholderQr().solve(-e);
    c += step.head<3>();
    if (nparam == 4) r += step(3);
    if (step.norm() < 1e-13) break;
  }
  f.center = c + mean;
  f.radius = r;
  double s2 = 0, lo = 1e300, hi = -1e300;
  for (const auto& p : pts) {
    const double dev = (p - f.center).norm() - r;
    s2 += dev * dev;
    lo = std::min(lo, dev);
    hi = std::max(hi, dev);
    f.max_abs_dev = std::max(f.max_abs_dev, std::abs(dev));
  }
  f.rms = std::sqrt(s2 / static_cast<double>(pts.size()));
  f.form_range = hi - lo;
  f.ok = std::isfinite(f.radius) && f.radius > 0;
  return f;
}

namespace {
struct Ball {
  Eigen::Vector3d c;
  double r2;
  bool contains(const Eigen::Vector3d& p) const { return (p - c).squaredNorm() <= r2 * (1 + 1e-9) + 1e-30; }
};

bool circumsphere(const std::vector<Eigen::Vector3d>& s, Ball& out) {
  if (s.size() == 1) {
    out = {s[0], 0};
    return true;
  }
  if (s.size() == 2) {
    out = {(s[0] + s[1]) / 2, (s[0] - s[1]).squaredNorm() / 4};
    return true;
  }
  // Centre in the affine hull: c = s0 + Σ λ_k (s_k − s0), with |c − s_k| = |c − s0|.
  const int m = static_cast<int>(s.size()) - 1;
  Eigen::MatrixXd M(m, m);
  Eigen::VectorXd rhs(m);
  for (int i = 0; i < m; ++i) {
    const Eigen::Vector3d ai = s[i + 1] - s[0];
    for (int j = 0; j < m; ++j) M(i, j) = 2 * ai.dot(s[j + 1] - s[0]);
    rhs(i) = ai.squaredNorm();
  }
  Eigen::FullPivLU<Eigen::MatrixXd> lu(M);
  if (!lu.isInvertible()) return false;
  const Eigen::VectorXd lambda = lu.solve(rhs);
  Eigen::Vector3d c = s[0];
  for (int j = 0; j < m; ++j) c += lambda(j) * (s[j + 1] - s[0]);
  out = {c, (c - s[0]).squaredNorm()};
  return true;
}
}  // namespace

double minimumEnclosingDiameter(const std::vector<Eigen::Vector3d>& input) {
  if (input.size() < 2) return 0;
  // Centred coordinates: the spheres here are tiny (µm) next to the coordinates (0.5 m).
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : input) mean += p;
  mean /= static_cast<double>(input.size());
  std::vector<Eigen::Vector3d> pts;
  for (const auto& p : input) pts.push_back(p - mean);
  // Exhaustive over supports of 2..4 points: exact, fine for the K = 5 centres of MPE_AL.
  double best = 1e300;
  const int n = static_cast<int>(pts.size());
  std::vector<int> idx;
  for (int mask = 1; mask < (1 << std::min(n, 16)); ++mask) {
    const int k = __builtin_popcount(static_cast<unsigned>(mask));
    if (k < 2 || k > 4) continue;
    std::vector<Eigen::Vector3d> s;
    for (int i = 0; i < n; ++i)
      if (mask & (1 << i)) s.push_back(pts[static_cast<size_t>(i)]);
    Ball b;
    if (!circumsphere(s, b) || b.r2 >= best * best / 4) continue;
    bool all = true;
    for (const auto& p : pts) all = all && b.contains(p);
    if (all) best = 2 * std::sqrt(b.r2);
  }
  return best;
}

PlaneFit fitPlane(const std::vector<Eigen::Vector3d>& pts) {
  PlaneFit f;
  if (pts.size() < 3) return f;
  Eigen::Vector3d mean = Eigen::Vector3d::Zero();
  for (const auto& p : pts) mean += p;
  mean /= static_cast<double>(pts.size());
  Eigen::Matrix3d C = Eigen::Matrix3d::Zero();
  for (const auto& p : pts) C += (p - mean) * (p - mean).transpose();
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> es(C);
  f.normal = es.eigenvectors().col(0);
  f.d = -f.normal.dot(mean);
  double s2 = 0, lo = 1e300, hi = -1e300;
  for (const auto& p : pts) {
    const double e = f.normal.dot(p) + f.d;
    s2 += e * e;
    lo = std::min(lo, e);
    hi = std::max(hi, e);
  }
  f.rms = std::sqrt(s2 / static_cast<double>(pts.size()));
  f.flatness = hi - lo;
  f.ok = true;
  return f;
}

}  // namespace cellsight
