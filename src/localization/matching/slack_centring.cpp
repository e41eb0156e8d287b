// After the polish: an accepted pose moved to the middle of the slack its scanned faces leave
// (mesh models only).
#include <limits>

#include "matching_internal.hpp"

namespace cellsight::matching_detail {

namespace {

/// Leaves out the rows over flat faces the scan did not see. Where a laser line runs off an
/// edge it reads a little below the face, and those points lie closer to the wall under the
/// edge than to the face they are on; matched to that wall they end the slack at once, wherever
/// the polish happened to stop. A face group whose rows all lie within icp_edge_band of its
/// creases (fewer than icp_edge_support beyond) holds only such points.
void dropUnseenFaces(const ModelMatcher::ModelIndex& m, const MatchingConfig& cfg, std::vector<PolishRow>& rows) {
  std::vector<int> support(m.faces.groups.size(), 0);
  std::vector<char> near(rows.size(), 0);
  for (size_t i = 0; i < rows.size(); ++i) {
    const PolishRow& r = rows[i];
    if (r.outside || r.tri < 0 || m.faces.group[r.tri] < 0) continue;
    near[i] = m.faces.creaseDistance(r.tri, r.q) < cfg.icp_edge_band;
    if (!near[i]) ++support[m.faces.group[r.tri]];
  }
  size_t kept = 0;
  for (size_t i = 0; i < rows.size(); ++i) {
    const PolishRow& r = rows[i];
    if (near[i] && support[m.faces.group[r.tri]] < cfg.icp_edge_support) continue;
    rows[kept++] = rows[i];
  }
  rows.resize(kept);
}

}  // namespace

/// Centres the pose in its slack. A part seen from one side is often pinned only by the ends
/// of its scanned faces: a flat top is free in-plane (two translations and the turn about its
/// normal) while its scanned patch stays inside the face, and the patch is smaller than the face
/// by what the scanner loses at edges (segment ends, the last line before an edge). ICP stops
/// where the first scan points reach an edge: one end of the slack. Here each direction the
/// points over faces constrain weakly (eigenvalues of their point-to-plane normal matrix below
/// icp_slack_eigen_ratio of the largest) is followed both ways to where the k-th point leaves
/// the surface (it moves off its face's plane by icp_slack_tolerance, or past one of the face's
/// creases: PlanarFaces), and the pose moves to the middle: the centre of the poses the scan
/// allows, exact when the scanner loses as much at opposite edges. Motions are linearised at the
/// polished pose (sub-millimetre and sub-degree). A direction bounded on one side or none (a
/// turn about an axis of symmetry) is left alone. Rotates the rows with the pose; returns the
/// change (model frame, applied after X).
Eigen::Isometry3d centreInSlack(const ModelMatcher::ModelIndex& m, std::vector<PolishRow>& rows, bool fresh,
                                const MatchingConfig& cfg, const Eigen::Vector3d* up) {
  Eigen::Isometry3d total = Eigen::Isometry3d::Identity();
  if (rows.size() < 20 || m.faces.groups.empty()) return total;
  const double L = std::max(0.5 * static_cast<double>(m.diameter), 1e-3);
  const double tol = cfg.icp_slack_tolerance;
  // rows measured before a last step that was not negligible: measure again at the final pose
  const float cap = static_cast<float>(std::max(2 * tol + 3 * cfg.icp_huber_floor, 0.001));
  for (auto& r : rows) {
    if (fresh) break;
    const ClosestPoint c = meshClosest(m, r.q.cast<float>(), cap);
    if (!c.found) {
      r.tri = -1;
      continue;
    }
    const Eigen::Vector3d dv = r.q - c.point.cast<double>(), nf = c.normal.cast<double>();
    const double d = dv.norm();
    r.tri = c.triangle;
    r.outside = !(d < 1e-9 || std::abs(nf.dot(dv)) >= 0.999 * d);
    r.n = r.outside ? Eigen::Vector3d(dv / d) : nf;
    r.r = r.outside ? d : nf.dot(dv);
  }
  if (cfg.icp_edge_band > 0) dropUnseenFaces(m, cfg, rows);
  Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Zero();
  std::vector<double> crease(rows.size());
  for (size_t i = 0; i < rows.size(); ++i) {
    const PolishRow& r = rows[i];
    if (r.tri < 0) continue;
    crease[i] = r.outside ? 0.0 : m.faces.creaseDistance(r.tri, r.q);
    if (r.outside) continue;
    Eigen::Matrix<double, 6, 1> J;
    J << r.q.cross(r.n) / L, r.n;
    A += J * J.transpose();
  }
  // tilt held: only the turn about `up` and the translations are followed
  const Eigen::Matrix<double, 6, Eigen::Dynamic> B = stepBasis(up);
  const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(B.transpose() * A * B);
  const Eigen::MatrixXd dirs = B * eig.eigenvectors();
  const double top = eig.eigenvalues().maxCoeff();
  if (!(top > 0)) return total;
  // the k-th point leaving ends the slack: a few stray points do not
  const size_t k = std::max<size_t>(static_cast<size_t>(cfg.icp_slack_points), rows.size() / 500);
  for (int pass = 0; pass < 2; ++pass) {
    for (int e = 0; e < static_cast<int>(dirs.cols()); ++e) {
      if (eig.eigenvalues()[e] > cfg.icp_slack_eigen_ratio * top) continue;
      const Eigen::Vector3d w = dirs.col(e).head<3>() / L, t = dirs.col(e).tail<3>();
      // a turn about an axis of symmetry (a sphere: any turn about its centre) moves nothing
      if (m.info.symmetry.type == Symmetry::Type::kSpherical && (w.cross(m.centroid) + t).norm() < 0.5 * w.norm() * L) continue;
      if (m.info.symmetry.type == Symmetry::Type::kAxial &&
          std::abs(w.dot(m.info.symmetry.axis.normalized())) * L > 0.9 * dirs.col(e).norm()) continue;
      // Each way: the motion at which the k-th point leaves. A first-order guess for every point
      // (off its face's plane, or across one of the face's creases) brackets it; the exact
      // closest point then decides, for the points the guess puts inside the bracket (a point
      // near a crease may just pass onto the next face, so guesses are only guesses).
      auto leaves = [&](size_t i, double tx) {
        const PolishRow& r = rows[i];
        const Eigen::Vector3d q = r.q + tx * (w.cross(r.q) + t);
        return !meshClosest(m, q.cast<float>(), static_cast<float>(std::abs(r.r) + tol)).found;
      };
      double end[2] = {0, 0}, first[2] = {0, 0};
      bool bounded = true;
      struct Guess {
        double lb, x;  // x < 0: not computed yet
        size_t i;
        Eigen::Vector3d vt;
      };
      std::vector<Guess> guesses[2];
      auto settle = [&](Guess& g) {
        if (g.x >= 0) return g.x;
        const double off = -g.x - 1;
        g.x = std::min(off, m.faces.creaseExit(rows[g.i].tri, rows[g.i].q, g.vt) + tol / g.vt.norm());
        return g.x;
      };
      for (int side = 0; side < 2 && bounded; ++side) {
        const double sgn = side ? -1.0 : 1.0;
        // lower bounds first (off the plane exactly; a crease no nearer than its distance), then
        // crease exits in order of the bound until the k-th smallest guess is settled
        std::vector<Guess>& guess = guesses[side];
        guess.reserve(rows.size());
        for (size_t i = 0; i < rows.size(); ++i) {
          const PolishRow& r = rows[i];
          if (r.tri < 0) continue;
          const Eigen::Vector3d v = sgn * (w.cross(r.q) + t);
          const double u = r.n.dot(v);
          Guess g{0, 0, i, Eigen::Vector3d::Zero()};
          if (r.outside) {
            g.x = u > 0 ? tol / u : std::numeric_limits<double>::infinity();
            g.lb = g.x;
          } else {
            g.x = u > 0 ? (std::abs(r.r) + tol - r.r) / u
                        : u < 0 ? (std::abs(r.r) + tol + r.r) / -u : std::numeric_limits<double>::infinity();
            g.vt = v - r.n * u;
            const double speed = g.vt.norm();
            g.lb = speed > 0 ? std::min(g.x, crease[i] / speed) : g.x;
            if (g.lb < g.x) g.x = -g.x - 1;  // crease exit still to compute (off-plane: -x - 1)
          }
          guess.push_back(g);
        }
        if (guess.size() < k) {
          bounded = false;
          break;
        }
        std::vector<double> kbest;  // max-heap of the k smallest settled guesses
        for (auto& g : guess) {
          if (kbest.size() == k && g.lb >= kbest.front()) continue;
          const double x = settle(g);
          if (kbest.size() < k) {
            kbest.push_back(x);
            std::push_heap(kbest.begin(), kbest.end());
          } else if (x < kbest.front()) {
            std::pop_heap(kbest.begin(), kbest.end());
            kbest.back() = x;
            std::push_heap(kbest.begin(), kbest.end());
          }
        }
        first[side] = kbest.front();
      }
      for (int side = 0; side < 2 && bounded; ++side) {
        const double sgn = side ? -1.0 : 1.0;
        std::vector<Guess>& guess = guesses[side];
        double hi = std::min(cfg.icp_slack_range, std::max(2 * first[side], 1e-5));
        std::vector<size_t> exits;
        for (;;) {
          exits.clear();
          for (auto& g : guess) {
            if (g.lb > 3 * hi || (g.x >= 0 && g.x > 3 * hi)) continue;  // beyond; unsettled: ask the mesh
            if (leaves(g.i, sgn * hi)) exits.push_back(g.i);
          }
          if (exits.size() >= k || hi >= cfg.icp_slack_range) break;
          hi = std::min(cfg.icp_slack_range, 4 * hi);
        }
        if (exits.size() < k) {
          bounded = false;
          break;
        }
        double lo = 0;  // allowed; hi: not allowed
        for (int it = 0; it < cfg.icp_slack_steps; ++it) {
          const double mid = 0.5 * (lo + hi);
          size_t n = 0;
          for (size_t j = 0; j < exits.size() && n < k; ++j) n += leaves(exits[j], sgn * mid) ? 1 : 0;
          (n < k ? lo : hi) = mid;
        }
        end[side] = lo;
      }
      if (!bounded) continue;
      const double hi = end[0], lo = -end[1];
      const double c = 0.5 * (hi + lo);
      Eigen::Isometry3d D = Eigen::Isometry3d::Identity();
      const Eigen::Vector3d wc = c * w;
      if (wc.norm() > 1e-15) D.linear() = Eigen::AngleAxisd(wc.norm(), wc.normalized()).toRotationMatrix();
      D.translation() = c * t;
      // the next direction starts from here: first-order distances, and crease distances kept
      // as lower bounds (less the point's move)
      for (size_t i = 0; i < rows.size(); ++i) {
        PolishRow& r = rows[i];
        const Eigen::Vector3d q = D * r.q;
        if (!r.outside) r.r += r.n.dot(q - r.q);
        crease[i] = std::max(0.0, crease[i] - (q - r.q).norm());
        r.q = q;
        r.n = D.linear() * r.n;
      }
      total = D * total;
    }
  }
  return total;
}

}  // namespace cellsight::matching_detail
