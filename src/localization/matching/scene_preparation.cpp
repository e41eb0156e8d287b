// Scene preparation: a cluster once for every model (voxels, normals, FPFH, ICP points,
// search structures), and the cloud conversions and thinning shared with the model index.
#include <pcl/features/fpfh.h>
#include <pcl/features/normal_3d.h>
#include <pcl/filters/voxel_grid.h>
#include <pcl/search/kdtree.h>

#include <tuple>

#include "matching_internal.hpp"

namespace cellsight::matching_detail {

pcl::PointCloud<pcl::PointXYZ>::Ptr toXyz(const std::vector<Vec3>& pts) {
  pcl::PointCloud<pcl::PointXYZ>::Ptr c(new pcl::PointCloud<pcl::PointXYZ>);
  c->resize(pts.size());
  for (size_t i = 0; i < pts.size(); ++i) (*c)[i].getVector3fMap() = pts[i];
  c->width = static_cast<uint32_t>(pts.size());
  c->height = 1;
  return c;
}

pcl::PointCloud<pcl::FPFHSignature33>::Ptr toPclFpfh(const std::vector<Fpfh>& f) {
  pcl::PointCloud<pcl::FPFHSignature33>::Ptr c(new pcl::PointCloud<pcl::FPFHSignature33>);
  c->resize(f.size());
  for (size_t i = 0; i < f.size(); ++i) std::copy(f[i].begin(), f[i].end(), (*c)[i].histogram);
  return c;
}

bool validFpfh(const Fpfh& f) {
  float s = 0;
  for (float v : f) {
    if (!std::isfinite(v)) return false;
    s += v;
  }
  return s > 0;
}

/// Thins a cloud with normals to one point per cell (the first one met).
ScanCloud thinned(const ScanCloud& c, double cell) {
  std::vector<std::pair<std::tuple<int, int, int>, int>> keys;
  keys.reserve(c.size());
  for (size_t i = 0; i < c.size(); ++i) {
    const Vec3 g = c.points[i] / static_cast<float>(cell);
    keys.push_back({{static_cast<int>(std::floor(g.x())), static_cast<int>(std::floor(g.y())), static_cast<int>(std::floor(g.z()))},
                    static_cast<int>(i)});
  }
  std::stable_sort(keys.begin(), keys.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
  ScanCloud out;
  out.frame_id = c.frame_id;
  for (size_t k = 0; k < keys.size(); ++k) {
    if (k > 0 && keys[k].first == keys[k - 1].first) continue;
    out.append(c.points[keys[k].second], 0.f);
    out.normals.push_back(c.normals[keys[k].second]);
  }
  return out;
}

/// The largest flat patch of a cluster: the plane through a coarse point along its normal that
/// most points lie on (within half the inlier distance, normals within 25°), refitted by PCA to
/// those points; found when they are at least 60 % of the points. A part seen mostly by
/// one face has it (the rest: a touching part, a rim), and so has one seen by a large face and a
/// few others whose pairs the PPF table cannot tell apart (a bracket on its side: its L face).
ScenePlane scenePlane(const ScanCloud& coarse, const MatchingConfig& cfg) {
  ScenePlane out;
  const size_t n_pts = coarse.size();
  if (n_pts < 10 || coarse.normals.size() != n_pts) return out;
  const float band = static_cast<float>(0.5 * cfg.inlier_distance);
  const float cos_n = std::cos(25.f * static_cast<float>(M_PI) / 180.f);
  auto inliers = [&](const Vec3& n, const Vec3& c, bool check_normals, std::vector<char>* in) {
    size_t count = 0;
    for (size_t i = 0; i < n_pts; ++i) {
      const bool ok = std::abs(n.dot(coarse.points[i] - c)) <= band &&
                      (!check_normals || std::abs(n.dot(coarse.normals[i])) >= cos_n);
      if (in) (*in)[i] = ok;
      count += ok;
    }
    return count;
  };
  // candidate planes: every point's own tangent plane, at most 128 of them spread over the cluster
  const size_t step = std::max<size_t>(1, n_pts / 128);
  size_t best = 0, best_i = 0;
  for (size_t i = 0; i < n_pts; i += step) {
    const Vec3& n = coarse.normals[i];
    if (!n.allFinite() || n.squaredNorm() < 0.5f) continue;
    const size_t c = inliers(n, coarse.points[i], true, nullptr);
    if (c > best) {
      best = c;
      best_i = i;
    }
  }
  if (best < 10) return out;
  std::vector<char> in(n_pts, 0);
  inliers(coarse.normals[best_i], coarse.points[best_i], true, &in);
  Vec3 n = coarse.normals[best_i], c = Vec3::Zero();
  Eigen::Matrix3f cov;
  size_t count = 0;
  for (int pass = 0; pass < 2; ++pass) {
    c.setZero();
    count = 0;
    for (size_t i = 0; i < n_pts; ++i)
      if (in[i]) {
        c += coarse.points[i];
        ++count;
      }
    if (count < 10) return out;
    c /= static_cast<float>(count);
    cov.setZero();
    for (size_t i = 0; i < n_pts; ++i)
      if (in[i]) cov += (coarse.points[i] - c) * (coarse.points[i] - c).transpose();
    Eigen::SelfAdjointEigenSolver<Eigen::Matrix3f> es(cov);
    n = es.eigenvectors().col(0);
    if (pass == 0) inliers(n, c, true, &in);
  }
  const double share = static_cast<double>(count) / static_cast<double>(n_pts);
  if (share < 0.6) return out;
  Eigen::SelfAdjointEigenSolver<Eigen::Matrix3f> es(cov);
  out.found = true;
  out.n = n.dot(cfg.viewpoint - c) < 0 ? -n : n;
  out.c = c;
  out.axis = es.eigenvectors().col(2).normalized();
  out.area = static_cast<float>(count) * static_cast<float>(cfg.voxel * cfg.voxel);
  return out;
}

std::unique_ptr<SceneData> prepareScene(const std::vector<Vec3>& finite, const MatchingConfig& cfg) {
  auto s = std::make_unique<SceneData>();
  s->all = finite;
  auto all = toXyz(finite);
  pcl::VoxelGrid<pcl::PointXYZ> vg;
  vg.setInputCloud(all);
  const float leaf = static_cast<float>(cfg.voxel);
  vg.setLeafSize(leaf, leaf, leaf);
  pcl::PointCloud<pcl::PointXYZ>::Ptr coarse(new pcl::PointCloud<pcl::PointXYZ>);
  vg.filter(*coarse);
  std::vector<Vec3> normals(coarse->size());
  if (cfg.scene_search == "grid") {
    // one grid serves the normals (radius normal_radius) and the fitness test (r_F)
    s->grid = PointGrid(finite, static_cast<float>(std::max(cfg.normal_radius, cfg.fitness_radius)));
    std::vector<Vec3> q(coarse->size());
    for (size_t i = 0; i < q.size(); ++i) q[i] = (*coarse)[i].getVector3fMap();
    normals = gridNormals(s->grid, q, static_cast<float>(cfg.normal_radius), cfg.viewpoint);
  } else {
    pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
    ne.setInputCloud(coarse);
    ne.setSearchSurface(all);
    ne.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
    ne.setRadiusSearch(cfg.normal_radius);
    ne.setViewPoint(cfg.viewpoint.x(), cfg.viewpoint.y(), cfg.viewpoint.z());
    pcl::PointCloud<pcl::Normal> n;
    ne.compute(n);
    for (size_t i = 0; i < n.size(); ++i) normals[i] = n[i].getNormalVector3fMap();
    s->tree.setInputCloud(all);
  }
  pcl::PointCloud<pcl::PointXYZ>::Ptr kept(new pcl::PointCloud<pcl::PointXYZ>);
  pcl::PointCloud<pcl::Normal>::Ptr kept_n(new pcl::PointCloud<pcl::Normal>);
  for (size_t i = 0; i < coarse->size(); ++i) {
    if (!normals[i].allFinite()) continue;
    kept->push_back((*coarse)[i]);
    pcl::Normal n;
    n.getNormalVector3fMap() = normals[i];
    kept_n->push_back(n);
    s->coarse.append((*coarse)[i].getVector3fMap(), 0.f);
    s->coarse.normals.push_back(normals[i].normalized());
  }
  if (kept->empty()) return s;
  s->ppf = thinned(s->coarse, cfg.ppf_sampling);
  const size_t cap = static_cast<size_t>(std::max(100.0, cfg.icp_max_points));
  const size_t step = std::max<size_t>(1, (finite.size() + cap - 1) / cap);
  for (size_t i = 0; i < finite.size(); i += step) s->icp_points.push_back(finite[i]);
  // a lower bound of the largest distance between two points (two farthest-point sweeps)
  auto farthest = [&](const Vec3& from) {
    size_t best = 0;
    float d = -1;
    for (size_t i = 0; i < s->coarse.size(); ++i) {
      const float di = (s->coarse.points[i] - from).squaredNorm();
      if (di > d) {
        d = di;
        best = i;
      }
    }
    return s->coarse.points[best];
  };
  const Vec3 b = farthest(s->coarse.points[0]), c = farthest(b);
  s->diameter = (b - c).norm();
  s->plane = scenePlane(s->coarse, cfg);
  if (cfg.coarse == "ppf" || cfg.descriptor == "learned") return s;  // the learned one: the matcher's
  pcl::FPFHEstimation<pcl::PointXYZ, pcl::Normal, pcl::FPFHSignature33> fe;
  fe.setInputCloud(kept);
  fe.setInputNormals(kept_n);
  fe.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
  fe.setRadiusSearch(cfg.feature_radius);
  pcl::PointCloud<pcl::FPFHSignature33> f;
  fe.compute(f);
  s->fpfh.resize(f.size());
  std::vector<Fpfh> valid;
  for (size_t i = 0; i < f.size(); ++i) {
    std::copy(f[i].histogram, f[i].histogram + 33, s->fpfh[i].begin());
    if (validFpfh(s->fpfh[i])) {
      s->fpfh_valid.push_back(static_cast<int>(i));
      valid.push_back(s->fpfh[i]);
    }
  }
  if (!valid.empty()) s->fpfh_tree.setInputCloud(toPclFpfh(valid));
  return s;
}

/// At most `cap` points: a voxel grid of `leaf` (cell centroids), then every k-th point.
std::vector<Vec3> capPoints(const std::vector<Vec3>& pts, double leaf, size_t cap) {
  pcl::VoxelGrid<pcl::PointXYZ> vg;
  vg.setInputCloud(toXyz(pts));
  const float l = static_cast<float>(leaf);
  vg.setLeafSize(l, l, l);
  pcl::PointCloud<pcl::PointXYZ> v;
  vg.filter(v);
  const size_t step = (v.size() + cap - 1) / cap;
  std::vector<Vec3> out;
  out.reserve(cap);
  for (size_t i = 0; i < v.size(); i += std::max<size_t>(1, step)) out.push_back(v[i].getVector3fMap());
  return out;
}

}  // namespace cellsight::matching_detail
