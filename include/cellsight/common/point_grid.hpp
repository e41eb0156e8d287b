// Fixed-radius neighbour queries on a uniform grid: points are sorted by cell once (O(n log n)),
// a query visits the cells its ball overlaps. For the small clouds of one part (a few thousand
// points, radius ~ cell) the scene stage took 1.8 ms with it where PCL's NormalEstimation and
// FLANN took 6.6 ms (a 2 300-point blade view, docs/localization.md); PCL stays the path for comparison
// (MatchingConfig::scene_search). Cells live in a dense array when the point set's box holds few
// enough of them, else in a hash map (a whole room scanned at millimetres).
#pragma once
#include <Eigen/Core>
#include <cmath>
#include <cstdint>
#include <unordered_map>
#include <vector>

namespace cellsight {

class PointGrid {
 public:
  PointGrid() = default;
  /// `cell` > 0 (metres); non-finite points are left out of every query.
  PointGrid(const std::vector<Eigen::Vector3f>& points, float cell);

  size_t size() const { return points_.size(); }
  const Eigen::Vector3f& point(size_t i) const { return points_[i]; }

  /// Calls fn(index, squared distance) for every point within r of q (index into the input).
  template <typename Fn>
  void forEachWithin(const Eigen::Vector3f& q, float r, Fn&& fn) const {
    visit(q, r, [&](uint32_t a, uint32_t b) {
      const float r2 = r * r;
      for (uint32_t k = a; k < b; ++k) {
        const float d2 = (sorted_[k] - q).squaredNorm();
        if (d2 <= r2) fn(index_[k], d2);
      }
      return true;
    });
  }

  /// Whether any point lies within r of q (stops at the first).
  bool anyWithin(const Eigen::Vector3f& q, float r) const {
    bool found = false;
    const float r2 = r * r;
    visit(q, r, [&](uint32_t a, uint32_t b) {
      for (uint32_t k = a; k < b; ++k) {
        if ((sorted_[k] - q).squaredNorm() <= r2) {
          found = true;
          return false;
        }
      }
      return true;
    });
    return found;
  }

 private:
  /// Calls range(begin, end) for the sorted points of each non-empty cell that the ball (q, r)
  /// overlaps, until it returns false.
  template <typename Range>
  void visit(const Eigen::Vector3f& q, float r, Range&& range) const {
    if (points_.empty() || !(r >= 0) || !q.allFinite()) return;
    const Eigen::Vector3f lo = (q - origin_).array() - r, hi = (q - origin_).array() + r;
    int c0[3], c1[3];
    for (int a = 0; a < 3; ++a) {
      const float l = std::floor(lo[a] * inv_cell_), h = std::floor(hi[a] * inv_cell_);
      if (h < 0 || l >= static_cast<float>(dims_[a])) return;
      c0[a] = l < 0 ? 0 : static_cast<int>(l);
      c1[a] = h >= static_cast<float>(dims_[a]) ? dims_[a] - 1 : static_cast<int>(h);
    }
    for (int z = c0[2]; z <= c1[2]; ++z) {
      for (int y = c0[1]; y <= c1[1]; ++y) {
        for (int x = c0[0]; x <= c1[0]; ++x) {
          const uint64_t key = (static_cast<uint64_t>(z) * dims_[1] + y) * dims_[0] + x;
          uint32_t a, b;
          if (!dense_.empty()) {
            a = dense_[key];
            b = dense_[key + 1];
          } else {
            const auto it = sparse_.find(key);
            if (it == sparse_.end()) continue;
            a = it->second.first;
            b = it->second.second;
          }
          if (a < b && !range(a, b)) return;
        }
      }
    }
  }

  float inv_cell_ = 0;
  Eigen::Vector3f origin_ = Eigen::Vector3f::Zero();
  int dims_[3] = {0, 0, 0};
  std::vector<Eigen::Vector3f> points_;  // as given
  std::vector<Eigen::Vector3f> sorted_;  // finite points, by cell
  std::vector<uint32_t> index_;          // sorted_ → points_
  std::vector<uint32_t> dense_;          // cell → first sorted point (one past the last cell: end)
  std::unordered_map<uint64_t, std::pair<uint32_t, uint32_t>> sparse_;
};

/// PCA normals of `queries` over the points of `grid` within `radius` (the eigenvector of the
/// smallest eigenvalue of their covariance), turned toward `viewpoint`; NaN where fewer than 3
/// points lie within the radius. The same estimate as PCL's NormalEstimation with a radius
/// search (test PointGrid.NormalsMatchPcl: < 1e-3 rad on a part's single view, and prints the
/// largest angle).
std::vector<Eigen::Vector3f> gridNormals(const PointGrid& grid, const std::vector<Eigen::Vector3f>& queries,
                                         float radius, const Eigen::Vector3f& viewpoint);

}  // namespace cellsight
