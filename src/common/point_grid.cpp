#include "cellsight/common/point_grid.hpp"

#include <Eigen/Eigenvalues>
#include <algorithm>
#include <limits>
#include <numeric>
#include <stdexcept>

namespace cellsight {

PointGrid::PointGrid(const std::vector<Eigen::Vector3f>& points, float cell) : points_(points) {
  if (!(cell > 0) || !std::isfinite(cell)) throw std::invalid_argument("PointGrid: cell must be > 0");
  inv_cell_ = 1.f / cell;
  Eigen::Vector3f lo = Eigen::Vector3f::Constant(std::numeric_limits<float>::max());
  Eigen::Vector3f hi = -lo;
  std::vector<uint32_t> finite;
  finite.reserve(points.size());
  for (size_t i = 0; i < points.size(); ++i) {
    if (!points[i].allFinite()) continue;
    finite.push_back(static_cast<uint32_t>(i));
    lo = lo.cwiseMin(points[i]);
    hi = hi.cwiseMax(points[i]);
  }
  if (finite.empty()) {
    points_.clear();
    return;
  }
  origin_ = lo;
  uint64_t cells = 1;
  for (int a = 0; a < 3; ++a) {
    const double n = std::floor((static_cast<double>(hi[a]) - lo[a]) / cell) + 1;
    if (n > 2e9) throw std::invalid_argument("PointGrid: cell too small for the points' extent");
    dims_[a] = static_cast<int>(n);
    cells = cells * static_cast<uint64_t>(dims_[a]);
    if (cells > (uint64_t{1} << 62)) throw std::invalid_argument("PointGrid: cell too small for the points' extent");
  }
  auto keyOf = [&](const Eigen::Vector3f& p) {
    const Eigen::Vector3f g = (p - origin_) * inv_cell_;
    const int x = std::min(dims_[0] - 1, static_cast<int>(g.x()));
    const int y = std::min(dims_[1] - 1, static_cast<int>(g.y()));
    const int z = std::min(dims_[2] - 1, static_cast<int>(g.z()));
    return (static_cast<uint64_t>(z) * dims_[1] + y) * dims_[0] + x;
  };
  std::vector<std::pair<uint64_t, uint32_t>> keyed(finite.size());
  for (size_t k = 0; k < finite.size(); ++k) keyed[k] = {keyOf(points[finite[k]]), finite[k]};
  std::sort(keyed.begin(), keyed.end());
  sorted_.resize(keyed.size());
  index_.resize(keyed.size());
  for (size_t k = 0; k < keyed.size(); ++k) {
    sorted_[k] = points[keyed[k].second];
    index_[k] = keyed[k].second;
  }
  // dense cell array while it stays within a few times the points (and 16 M cells)
  if (cells <= std::max<uint64_t>(1 << 16, 8 * keyed.size()) && cells <= (1 << 24)) {
    dense_.assign(cells + 1, 0);
    for (const auto& k : keyed) ++dense_[k.first + 1];
    std::partial_sum(dense_.begin(), dense_.end(), dense_.begin());
  } else {
    sparse_.reserve(keyed.size());
    for (size_t a = 0; a < keyed.size();) {
      size_t b = a;
      while (b < keyed.size() && keyed[b].first == keyed[a].first) ++b;
      sparse_.emplace(keyed[a].first, std::make_pair(static_cast<uint32_t>(a), static_cast<uint32_t>(b)));
      a = b;
    }
  }
}

std::vector<Eigen::Vector3f> gridNormals(const PointGrid& grid, const std::vector<Eigen::Vector3f>& queries,
                                         float radius, const Eigen::Vector3f& viewpoint) {
  std::vector<Eigen::Vector3f> out(queries.size(), Eigen::Vector3f::Constant(std::numeric_limits<float>::quiet_NaN()));
  for (size_t i = 0; i < queries.size(); ++i) {
    const Eigen::Vector3f& q = queries[i];
    // moments about the query point (it lies among its neighbours: no cancellation), summed in
    // float — the normals stay within 0.02° of a double sum (measured on a housing view)
    Eigen::Vector3f s1 = Eigen::Vector3f::Zero();
    Eigen::Matrix3f s2 = Eigen::Matrix3f::Zero();
    int n = 0;
    grid.forEachWithin(q, radius, [&](uint32_t j, float) {
      const Eigen::Vector3f d = grid.point(j) - q;
      s1 += d;
      s2.noalias() += d * d.transpose();
      ++n;
    });
    if (n < 3) continue;
    const Eigen::Vector3d mean = s1.cast<double>() / n;
    const Eigen::Matrix3d cov = s2.cast<double>() / n - mean * mean.transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3d> eig;
    eig.computeDirect(cov);
    Eigen::Vector3f normal = eig.eigenvectors().col(0).cast<float>();
    if (!normal.allFinite()) continue;
    if (normal.dot(viewpoint - q) < 0) normal = -normal;
    out[i] = normal;
  }
  return out;
}

}  // namespace cellsight
