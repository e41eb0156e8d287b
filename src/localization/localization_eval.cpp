#include "cellsight/localization/localization_eval.hpp"

#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/point_types.h>

#include <algorithm>
#include <cmath>

#include "cellsight/localization/model_library.hpp"
#include "cellsight/common/raycaster.hpp"

namespace cellsight {

ScanCloud singleViewCloud(const TriangleMesh& mesh, const Eigen::Isometry3d& T, const Eigen::Vector3f& viewpoint,
                          double spacing, double noise, uint64_t seed, double max_view_angle) {
  // cell centroids: the clustering node hands the matcher a 1 mm voxel grid of the scan
  const ScanCloud model = sampleMesh(mesh, spacing, seed, CellSample::kCentroid);
  RayCaster rc;
  rc.addMesh(mesh, T);
  rc.commit();
  std::mt19937_64 rng(seed + 1);
  std::normal_distribution<float> N(0.f, static_cast<float>(noise));
  const Eigen::Isometry3f Tf = T.cast<float>();
  const float cos_max = std::cos(static_cast<float>(max_view_angle));
  ScanCloud out;
  out.frame_id = "base_link";
  for (size_t i = 0; i < model.size(); ++i) {
    const Eigen::Vector3f p = Tf * model.points[i], n = Tf.linear() * model.normals[i];
    Eigen::Vector3f ray = p - viewpoint;
    const float d = ray.norm();
    ray /= d;
    if (-n.dot(ray) < cos_max) continue;
    if (rc.occluded(viewpoint, ray, 0.f, d - 0.0005f)) continue;
    out.append(p + (noise > 0 ? N(rng) : 0.f) * ray, 1.f);
    out.normals.push_back(n);
  }
  return out;
}

ScanCloud randomWalkOcclusion(const ScanCloud& cloud, double share, int k_s, std::mt19937_64& rng) {
  const size_t n = cloud.size();
  const size_t target = static_cast<size_t>(std::round(std::clamp(share, 0.0, 1.0) * n));
  if (n == 0 || target == 0) return cloud;
  pcl::PointCloud<pcl::PointXYZ>::Ptr pc(new pcl::PointCloud<pcl::PointXYZ>);
  for (const auto& p : cloud.points) pc->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
  pcl::KdTreeFLANN<pcl::PointXYZ> tree;
  tree.setInputCloud(pc);
  std::vector<char> removed(n, 0);
  size_t gone = 0;
  std::uniform_int_distribution<size_t> pick(0, n - 1);
  size_t start = pick(rng);
  std::vector<int> idx;
  std::vector<float> d2;
  while (gone < target) {
    if (removed[start]) {  // walked into a hole: restart from a random remaining point
      do start = pick(rng);
      while (removed[start]);
    }
    // nearest remaining neighbours (search wider until k_s remain or the cloud is exhausted)
    std::vector<std::pair<float, int>> alive;
    for (int k = k_s + 1; alive.size() < static_cast<size_t>(k_s) + 1; k *= 2) {
      alive.clear();
      tree.nearestKSearch((*pc)[start], std::min<int>(k, static_cast<int>(n)), idx, d2);
      for (size_t j = 0; j < idx.size(); ++j)
        if (!removed[idx[j]]) alive.push_back({d2[j], idx[j]});
      if (k >= static_cast<int>(n)) break;
    }
    if (alive.empty()) break;
    const int farthest = alive.back().second;
    for (size_t j = 0; j + 1 < alive.size() && gone < target; ++j) {
      removed[alive[j].second] = 1;
      ++gone;
    }
    if (alive.size() == 1 && gone < target) {
      removed[farthest] = 1;
      ++gone;
    }
    start = static_cast<size_t>(farthest);
  }
  ScanCloud out;
  out.frame_id = cloud.frame_id;
  const bool has_n = cloud.normals.size() == n;
  for (size_t i = 0; i < n; ++i) {
    if (removed[i]) continue;
    out.append(cloud.points[i], i < cloud.intensity.size() ? cloud.intensity[i] : 0.f);
    if (has_n) out.normals.push_back(cloud.normals[i]);
  }
  return out;
}

ScanCloud addUniformOutliers(const ScanCloud& cloud, const Eigen::AlignedBox3f& box, double ratio, std::mt19937_64& rng) {
  ScanCloud out = cloud;
  const size_t extra = static_cast<size_t>(std::round(std::max(0.0, ratio) * cloud.size()));
  std::uniform_real_distribution<float> U(0.f, 1.f);
  std::normal_distribution<float> N(0.f, 1.f);
  const bool has_n = cloud.normals.size() == cloud.size();
  for (size_t i = 0; i < extra; ++i) {
    const Eigen::Vector3f u(U(rng), U(rng), U(rng));
    out.append(box.min() + u.cwiseProduct(box.sizes()), 0.f);
    if (has_n) out.normals.push_back(Eigen::Vector3f(N(rng), N(rng), N(rng)).normalized());
  }
  return out;
}

}  // namespace cellsight
