// PCL-heavy translation unit.
#include "cellsight/localization/clustering.hpp"

#include <pcl/filters/voxel_grid.h>
#include <pcl/point_types.h>
#include <pcl/sample_consensus/method_types.h>
#include <pcl/sample_consensus/model_types.h>
#include <pcl/search/kdtree.h>
#include <pcl/segmentation/extract_clusters.h>
#include <pcl/segmentation/sac_segmentation.h>

#include <algorithm>
#include <cmath>
#include <unordered_set>

#include "cellsight/common/yaml_reader.hpp"
#include "cellsight/common/pcl_cloud.hpp"

namespace cellsight {

namespace {

/// Spacing of the support points kept for the matcher's free-space test (base x / y), m.
constexpr double kSupportCell = 0.002;
using PointT = pcl::PointXYZI;

pcl::PointCloud<PointT>::Ptr voxelise(const pcl::PointCloud<PointT>::Ptr& in, double leaf) {
  pcl::VoxelGrid<PointT> vg;
  vg.setInputCloud(in);
  vg.setLeafSize(static_cast<float>(leaf), static_cast<float>(leaf), static_cast<float>(leaf));
  auto out = pcl::make_shared<pcl::PointCloud<PointT>>();
  vg.filter(*out);
  return out;
}
}  // namespace

ClusteringResult clusterScene(const ScanCloud& scene, const ClusteringConfig& cfg) {
  ClusteringResult r;
  r.input_points = scene.size();
  ScanCloud finite = scene;
  r.non_finite = removeNonFinite(finite);
  if (r.non_finite > 0) r.warnings.push_back(std::to_string(r.non_finite) + " non-finite points dropped");
  if (cfg.crop) finite = cropBox(finite, cfg.workspace);
  r.after_crop = finite.size();
  if (finite.size() == 0) {
    r.warnings.push_back(scene.size() == 0 ? "empty cloud: nothing to segment"
                                           : "no finite point inside the workspace: nothing to segment");
    return r;
  }
  auto cloud = toPclXyzi<PointT>(finite);
  double leaf = cfg.voxel_size;
  if (cloud->size() > cfg.max_input_points) {
    // Memory bound for huge scenes: a leaf that brings the cloud near the limit.
    const Eigen::AlignedBox3f b = [&] {
      Eigen::AlignedBox3f x;
      for (const auto& p : finite.points) x.extend(p);
      return x;
    }();
    const double area = std::max(1e-6, static_cast<double>(b.sizes().x() * b.sizes().y()));
    leaf = std::max(leaf, std::sqrt(area / static_cast<double>(cfg.max_input_points)) * 1.5);
    r.warnings.push_back(std::to_string(cloud->size()) + " points exceed max_input_points " +
                         std::to_string(cfg.max_input_points) + ": voxelised at " + std::to_string(leaf * 1e3) + " mm");
  }
  if (leaf > 0) cloud = voxelise(cloud, leaf);
  r.after_voxel = cloud->size();
  if (cfg.remove_plane && cloud->size() >= 3) {
    pcl::SACSegmentation<PointT> seg;
    seg.setOptimizeCoefficients(true);
    seg.setModelType(pcl::SACMODEL_PERPENDICULAR_PLANE);
    seg.setAxis(cfg.up);
    seg.setEpsAngle(cfg.plane_max_tilt);
    seg.setMethodType(pcl::SAC_RANSAC);
    seg.setDistanceThreshold(cfg.plane_distance);
    seg.setMaxIterations(cfg.plane_iterations);
    seg.setInputCloud(cloud);
    pcl::PointIndices inliers;
    pcl::ModelCoefficients coeff;
    seg.segment(inliers, coeff);
    if (inliers.indices.size() >= cfg.plane_min_share * cloud->size() && coeff.values.size() == 4) {
      r.plane_found = true;
      Eigen::Vector3d n(coeff.values[0], coeff.values[1], coeff.values[2]);
      double d = coeff.values[3];
      const double norm = n.norm();
      n /= norm;
      d /= norm;
      if (n.dot(cfg.up.cast<double>()) < 0) {
        n = -n;
        d = -d;
      }
      r.support.n = n;
      r.support.d = d;
      // Keep what lies above the plane by more than the inlier band; the band itself is the
      // support seen, kept one point per 2 mm cell.
      auto above = pcl::make_shared<pcl::PointCloud<PointT>>();
      std::unordered_set<uint64_t> cells;
      for (const auto& p : *cloud) {
        const double h = r.support.distance(Eigen::Vector3d(p.x, p.y, p.z));
        if (h > cfg.plane_distance) {
          above->push_back(p);
        } else if (h >= -cfg.plane_distance && std::isfinite(p.x) && std::isfinite(p.y)) {
          const auto ix = static_cast<int64_t>(std::floor(p.x / kSupportCell)),
                     iy = static_cast<int64_t>(std::floor(p.y / kSupportCell));
          if (cells.insert((static_cast<uint64_t>(ix) << 32) ^ static_cast<uint64_t>(iy & 0xffffffff)).second)
            r.support_points.emplace_back(p.x, p.y, p.z);
        }
      }
      cloud = above;
    } else {
      r.warnings.push_back("no support plane found (largest horizontal plane holds " +
                           std::to_string(inliers.indices.size()) + " of " + std::to_string(cloud->size()) + " points)");
    }
  }
  r.after_plane = cloud->size();
  if (cloud->empty()) {
    r.warnings.push_back("nothing left above the support plane");
    return r;
  }
  // Clustering space: the points themselves, or their projections on the support plane.
  auto space = cloud;
  if (cfg.cluster_in_plane && r.plane_found) {
    space = pcl::make_shared<pcl::PointCloud<PointT>>(*cloud);
    for (auto& p : *space) {
      const Eigen::Vector3d q(p.x, p.y, p.z);
      const Eigen::Vector3d proj = q - r.support.distance(q) * r.support.n;
      p.x = static_cast<float>(proj.x());
      p.y = static_cast<float>(proj.y());
      p.z = static_cast<float>(proj.z());
    }
  }
  auto tree = pcl::make_shared<pcl::search::KdTree<PointT>>();
  tree->setInputCloud(space);
  std::vector<pcl::PointIndices> found;
  pcl::EuclideanClusterExtraction<PointT> ec;
  ec.setClusterTolerance(cfg.cluster_tolerance);
  ec.setMinClusterSize(1);  // the small groups are kept as fragments
  ec.setMaxClusterSize(cfg.max_cluster_points);
  ec.setSearchMethod(tree);
  ec.setInputCloud(space);
  ec.extract(found);
  for (const auto& idx : found) {
    if (idx.indices.size() < static_cast<size_t>(cfg.min_cluster_points)) {
      for (int i : idx.indices) {
        const auto& p = (*cloud)[static_cast<size_t>(i)];
        r.fragments.emplace_back(p.x, p.y, p.z);
      }
      continue;
    }
    SceneCluster c;
    c.cloud.frame_id = scene.frame_id;
    for (int i : idx.indices) {
      const auto& p = (*cloud)[static_cast<size_t>(i)];
      const Eigen::Vector3f q(p.x, p.y, p.z);
      c.cloud.append(q, p.intensity);
      c.box.extend(q);
      c.centroid += q;
    }
    c.centroid /= static_cast<float>(c.cloud.size());
    r.clusters.push_back(std::move(c));
  }
  std::sort(r.clusters.begin(), r.clusters.end(),
            [](const SceneCluster& a, const SceneCluster& b) { return a.cloud.size() > b.cloud.size(); });
  return r;
}

ClusteringConfig loadClusteringConfig(const std::string& path) {
  YamlMap m(loadYamlFile(path), path);
  ClusteringConfig c;
  if (m.has("workspace_min") || m.has("workspace_max")) {
    const Eigen::Vector3f lo = m.getVector3("workspace_min").cast<float>(), hi = m.getVector3("workspace_max").cast<float>();
    if ((hi.array() <= lo.array()).any()) m.fail("workspace_max", "must exceed workspace_min on every axis");
    c.crop = true;
    c.workspace = Eigen::AlignedBox3f(lo, hi);
  }
  c.voxel_size = m.getDouble("voxel_size", c.voxel_size);
  if (c.voxel_size < 0) m.fail("voxel_size", "must be >= 0 (0 disables)");
  c.remove_plane = m.getBool("remove_plane", c.remove_plane);
  c.plane_distance = m.getDouble("plane_distance", c.plane_distance);
  if (c.plane_distance <= 0) m.fail("plane_distance", "must be > 0");
  c.plane_iterations = m.getInt("plane_iterations", c.plane_iterations);
  c.up = m.getVector3("up", c.up.cast<double>()).normalized().cast<float>();
  c.plane_max_tilt = m.getDouble("plane_max_tilt", c.plane_max_tilt);
  c.plane_min_share = m.getDouble("plane_min_share", c.plane_min_share);
  c.cluster_tolerance = m.getDouble("cluster_tolerance", c.cluster_tolerance);
  c.cluster_in_plane = m.getBool("cluster_in_plane", c.cluster_in_plane);
  if (c.cluster_tolerance <= 0) m.fail("cluster_tolerance", "must be > 0");
  c.min_cluster_points = m.getInt("min_cluster_points", c.min_cluster_points);
  c.max_cluster_points = m.getInt("max_cluster_points", c.max_cluster_points);
  if (c.max_cluster_points < c.min_cluster_points) m.fail("max_cluster_points", "must be >= min_cluster_points");
  const int max_input = m.getInt("max_input_points", static_cast<int>(c.max_input_points));
  if (max_input < 1000) m.fail("max_input_points", "must be >= 1000 (got " + std::to_string(max_input) + ")");
  c.max_input_points = static_cast<size_t>(max_input);
  if (c.min_cluster_points < 1) m.fail("min_cluster_points", "must be >= 1");
  m.finish();
  return c;
}

}  // namespace cellsight
