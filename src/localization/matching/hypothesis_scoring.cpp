// Coarse hypotheses, shared by the PPF and RANSAC stages: a pose's score on the model's
// distance field, and whether two poses are distinct.
#include "matching_internal.hpp"

namespace cellsight::matching_detail {

int scoreHypothesis(const SceneData& s, const std::vector<int>& order, const ModelMatcher::ModelIndex& m,
                    const Eigen::Isometry3f& T, float inlier2, float cos_normal, int probe, double floor_share) {
  const Eigen::Isometry3f Ti = T.inverse();
  const Eigen::Matrix3f Rt = Ti.linear();
  const auto& fp = m.fine->points;
  const auto& fn = m.fine->normals;
  int count = 0;
  for (size_t k = 0; k < order.size(); ++k) {
    if (static_cast<int>(k) == probe && count < floor_share * probe) return count * static_cast<int>(order.size()) / probe;
    const int i = order[k];
    const Vec3 q = Ti * s.coarse.points[i];
    const int j = m.field.lookup(q);
    if (j < 0) continue;
    if ((q - fp[j]).squaredNorm() > inlier2) continue;
    if ((Rt * s.coarse.normals[i]).dot(fn[j]) < cos_normal) continue;
    ++count;
  }
  return count;
}

bool distinct(const Eigen::Isometry3f& a, const Eigen::Isometry3f& b, float dt) {
  if ((a.translation() - b.translation()).norm() > dt) return true;
  const Eigen::AngleAxisf d(a.linear().transpose() * b.linear());
  return std::abs(d.angle()) > 0.2f;
}

}  // namespace cellsight::matching_detail
