// Fine stage: robust point-to-plane ICP on the distance field, then an exact polish against
// the mesh's closest points (or the fine samples' k-d tree for cloud models).
#include "matching_internal.hpp"

namespace cellsight::matching_detail {

/// The mesh's closest point to q (model frame) within max_d: the candidate grid, else Embree.
ClosestPoint meshClosest(const ModelMatcher::ModelIndex& m, const Eigen::Vector3f& q, float max_d) {
  bool covered = false;
  ClosestPoint c;
  if (!m.closest.empty()) c = m.closest.closestPoint(q, max_d, &covered);
  if (!covered && !(m.closest.margin() >= max_d)) c = m.caster.closestPoint(q, max_d);
  return c;
}

Eigen::Matrix<double, 6, Eigen::Dynamic> stepBasis(const Eigen::Vector3d* up) {
  if (!up) return Eigen::Matrix<double, 6, 6>::Identity();
  Eigen::Matrix<double, 6, 4> B = Eigen::Matrix<double, 6, 4>::Zero();
  B.block<3, 1>(0, 0) = up->normalized();
  B.block<3, 3>(3, 1) = Eigen::Matrix3d::Identity();
  return B;
}

/// Robust point-to-plane ICP of the scene points onto the model (Huber weights, shrinking
/// correspondence distance); distance-field correspondences, then exact ones.
/// `max_points`: the scene points used (evenly thinned); `polish`: finish with exact neighbours.
Refined icp(const SceneData& s, const ModelMatcher::ModelIndex& m, const Eigen::Isometry3f& T0,
            const MatchingConfig& cfg, size_t max_points, bool polish, const Eigen::Vector3d* up) {
  const size_t stride = std::max<size_t>(1, (s.icp_points.size() + max_points - 1) / std::max<size_t>(1, max_points));
  Eigen::Isometry3d X = T0.inverse().cast<double>();  // scene → model
  const auto& fp = m.fine->points;
  const auto& fn = m.fine->normals;
  double dmax = std::max(2 * cfg.inlier_distance, 4 * cfg.icp_spacing);
  const double dmin = std::max(3 * cfg.icp_spacing, 0.5 * cfg.fitness_radius);
  const int exact_iterations = cfg.icp_exact_iterations;
  double rmse = 0;
  int exact_done = 0;
  // eigenvalues below this share of the largest are taken as unconstrained directions
  const double degenerate_ratio = 1e-6;
  std::vector<int> idx(1);
  std::vector<float> d2(1);
  std::vector<double> res;
  Eigen::Matrix<double, 6, 1> prev_step = Eigen::Matrix<double, 6, 1>::Zero();  // scaled
  std::vector<PolishRow> polished;  // the last exact iteration's rows (at the final pose)
  bool polished_fresh = false;      // measured within a converged step of the final pose
  for (int it = 0; it < cfg.icp_iterations + (polish ? exact_iterations : 0); ++it) {
    const bool exact = it >= cfg.icp_iterations || exact_done > 0;
    Eigen::Matrix<double, 6, 6> A = Eigen::Matrix<double, 6, 6>::Zero();
    Eigen::Matrix<double, 6, 1> b = Eigen::Matrix<double, 6, 1>::Zero();
    using Row = PolishRow;
    std::vector<Row> rows;
    rows.reserve(s.icp_points.size() / stride + 1);
    for (size_t pi = 0; pi < s.icp_points.size(); pi += stride) {
      const Vec3& p = s.icp_points[pi];
      const Eigen::Vector3d q = X * p.cast<double>();
      int j;
      if (exact && m.has_mesh && cfg.icp_mesh_polish) {
        // exact: the closest point of the mesh itself. A scan point beyond a face's edge is
        // pulled back over the edge; against the nearest sample's tangent plane it would not
        // be (the plane runs on past the edge), and a flat part could slide.
        const ClosestPoint c = meshClosest(m, q.cast<float>(), static_cast<float>(dmax));
        if (!c.found) continue;
        const Eigen::Vector3d cp = c.point.cast<double>(), nf = c.normal.cast<double>(), dv = q - cp;
        const double dist = dv.norm();
        if (dist < 1e-9 || std::abs(nf.dot(dv)) >= 0.999 * dist) {
          rows.push_back({q, nf, nf.dot(dv), c.triangle, false});  // over the face: point-to-plane
        } else {
          rows.push_back({q, dv / dist, dist, c.triangle, true});  // beyond an edge or corner: toward it
        }
        continue;
      }
      if (exact) {
        pcl::PointXYZ qq(static_cast<float>(q.x()), static_cast<float>(q.y()), static_cast<float>(q.z()));
        if (m.fine_tree.nearestKSearch(qq, 1, idx, d2) < 1) continue;
        j = idx[0];
      } else {
        j = m.field.lookup(q.cast<float>());
        if (j < 0) continue;
      }
      const Eigen::Vector3d mp = fp[j].cast<double>(), n = fn[j].cast<double>();
      if ((q - mp).norm() > dmax) continue;
      rows.push_back({q, n, n.dot(q - mp), -1, false});
    }
    if (rows.size() < 6) break;
    // robust scale from the median absolute residual of every k-th row (256–511 rows: it sets
    // the Huber scale and the next correspondence distance, where a few per cent do not matter)
    const size_t every = std::max<size_t>(1, rows.size() / 256);
    res.clear();
    for (size_t i = 0; i < rows.size(); i += every) res.push_back(std::abs(rows[i].r));
    std::nth_element(res.begin(), res.begin() + res.size() / 2, res.end());
    const double sigma = std::max(1.4826 * res[res.size() / 2], 1e-5);
    // Huber scale from the residuals, but not below the floor: with a clean scan sigma is a few
    // hundredths of a millimetre, and a smaller scale would damp the few points on side walls
    // and edges — the only ones that fix a flat part's in-plane position — to a crawl.
    const double huber = std::max(1.5 * sigma, cfg.icp_huber_floor);
    double ss = 0;
    for (const auto& row : rows) {
      const double w = std::abs(row.r) <= huber ? 1.0 : huber / std::abs(row.r);
      Eigen::Matrix<double, 6, 1> J;
      J << row.q.cross(row.n), row.n;
      for (int i = 0; i < 6; ++i) {  // upper triangle only (A is symmetric)
        const double wi = w * J[i];
        for (int j = i; j < 6; ++j) A(i, j) += wi * J[j];
      }
      b -= w * J * row.r;
      ss += row.r * row.r;
    }
    A.triangularView<Eigen::StrictlyLower>() = A.transpose();
    rmse = std::sqrt(ss / rows.size());
    // Degeneracy-aware step: directions the data do not constrain (a U-profile seen from
    // above says nothing along its extrusion; exact face normals make that exactly singular)
    // get no step instead of an arbitrary one. Rotation is scaled by the part's size so that
    // the eigenvalues compare like with like.
    const double L = std::max(0.5 * static_cast<double>(m.diameter), 1e-3);
    Eigen::Matrix<double, 6, 1> scale;
    scale << L, L, L, 1, 1, 1;
    const Eigen::Matrix<double, 6, 6> As = scale.asDiagonal().inverse() * A * scale.asDiagonal().inverse();
    // tilt held: steps lie in the span of the turn about the support's normal (in the model
    // frame at the current pose) and the three translations
    Eigen::Vector3d up_model;
    if (up) up_model = X.linear() * *up;  // X: scene → model
    const Eigen::Matrix<double, 6, Eigen::Dynamic> B = stepBasis(up ? &up_model : nullptr);
    const Eigen::MatrixXd Ab = B.transpose() * As * B;
    const Eigen::SelfAdjointEigenSolver<Eigen::MatrixXd> eig(Ab);
    const double floor_ev = degenerate_ratio * eig.eigenvalues().maxCoeff();
    Eigen::Matrix<double, 6, 1> xs = Eigen::Matrix<double, 6, 1>::Zero();
    const Eigen::VectorXd bs = B.transpose() * (scale.asDiagonal().inverse() * b);
    for (int k = 0; k < static_cast<int>(Ab.rows()); ++k) {
      const double ev = eig.eigenvalues()[k];
      if (ev > floor_ev && ev > 0) xs += B * eig.eigenvectors().col(k) * (eig.eigenvectors().col(k).dot(bs) / ev);
    }
    const Eigen::Matrix<double, 6, 1> x = scale.asDiagonal().inverse() * xs;
    if (!x.allFinite()) break;
    Eigen::Isometry3d D = Eigen::Isometry3d::Identity();
    const double angle = x.head<3>().norm();
    if (angle > 1e-12) D.linear() = Eigen::AngleAxisd(angle, x.head<3>() / angle).toRotationMatrix();
    D.translation() = x.tail<3>();
    X = D * X;
    if (exact && m.has_mesh && cfg.icp_mesh_polish) {
      polished = std::move(rows);
      for (auto& row : polished) row.q = D * row.q;
    }
    dmax = std::max(dmin, std::min(dmax, 4 * sigma + cfg.icp_spacing));
    // converged: the field's correspondences are good to its cell, so stop them at 10 µm steps;
    // the exact polish stops at 1 µm
    const double tol = exact ? 1e-6 : 1e-5;
    // a turn about an axis of symmetry (or any turn of a sphere about its centre) changes
    // nothing: it does not count as motion
    Eigen::Vector3d w = x.head<3>(), v = x.tail<3>();
    if (m.info.symmetry.type == Symmetry::Type::kAxial) {
      const Eigen::Vector3d a = m.info.symmetry.axis.normalized();
      w -= a * a.dot(w);
    } else if (m.info.symmetry.type == Symmetry::Type::kSpherical) {
      v += w.cross(m.centroid);
      w.setZero();
    }
    // on the field, a step that turns back on the previous one is its quantisation (nearest
    // sample per cell) bouncing the pose around the minimum: converged as far as it can tell
    const bool bounced = !exact && it > 0 && xs.dot(prev_step) < 0;
    prev_step = xs;
    const bool small = (w.norm() < 10 * tol && v.norm() < tol) || bounced;
    if (exact) {
      polished_fresh = small;
      if (++exact_done >= exact_iterations || small) break;
    } else if (small) {
      if (!polish) break;
      exact_done = 1;  // converged on the field: polish with exact neighbours
    }
  }
  Refined r;
  r.T = X.inverse().cast<float>();
  r.rmse = rmse;
  r.polished = std::move(polished);
  r.polished_fresh = polished_fresh;
  return r;
}

}  // namespace cellsight::matching_detail
