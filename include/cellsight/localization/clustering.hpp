// Scene segmentation before model matching (thesis §3): crop to the workspace, voxel
// downsampling (cell centroids), support-plane removal (RANSAC), Euclidean clustering (flood fill
// through neighbours within a tolerance) with size limits. PCL does the work in clustering.cpp.
#pragma once
#include <Eigen/Geometry>
#include <string>
#include <vector>

#include "cellsight/common/plane.hpp"
#include "cellsight/common/scan_cloud.hpp"

namespace cellsight {

struct ClusteringConfig {
  bool crop = false;
  Eigen::AlignedBox3f workspace;          ///< base frame, used when crop
  double voxel_size = 0.001;              ///< m; 0 disables downsampling
  bool remove_plane = true;
  double plane_distance = 0.0015;         ///< m, RANSAC inlier threshold
  int plane_iterations = 300;
  Eigen::Vector3f up = Eigen::Vector3f::UnitZ();  ///< the support plane's expected normal
  double plane_max_tilt = 0.26;           ///< rad between the plane normal and `up`
  double plane_min_share = 0.15;          ///< smaller planes are not the support
  double cluster_tolerance = 0.008;       ///< m
  /// Cluster the points' projections on the support plane (when one was found): a single-view
  /// scan sees a part as separate patches at different heights (tops, floors of pockets) that
  /// touch only when seen from above. Parts standing apart on the support stay apart.
  bool cluster_in_plane = true;
  int min_cluster_points = 50;
  int max_cluster_points = 500000;
  size_t max_input_points = 3000000;      ///< larger inputs are voxelised first (with a warning)
};

struct SceneCluster {
  ScanCloud cloud;
  Eigen::Vector3f centroid = Eigen::Vector3f::Zero();
  Eigen::AlignedBox3f box;
};

struct ClusteringResult {
  std::vector<SceneCluster> clusters;  ///< largest first
  bool plane_found = false;
  Plane support;                  ///< the removed support plane (base frame)
  /// where the scan saw the support: its inliers, one per 2 mm cell (the matcher's free-space
  /// test: a part cannot stand where the camera saw the table behind it)
  std::vector<Eigen::Vector3f> support_points;
  /// the points above the support in groups smaller than min_cluster_points: not searched, but
  /// measured surface all the same (a bracket standing on its side shows its top face and, apart
  /// from it, the top of its foot): the matcher's fitness and unseen tests count them
  std::vector<Eigen::Vector3f> fragments;
  size_t input_points = 0, after_crop = 0, after_voxel = 0, after_plane = 0, non_finite = 0;
  std::vector<std::string> warnings;  ///< e.g. empty input, downsampled huge input
};

/// Segments a scan. Never throws for bad data: empty or all-NaN clouds give no clusters and a
/// warning; non-finite points are dropped and counted.
ClusteringResult clusterScene(const ScanCloud& scene, const ClusteringConfig& config);

/// Strict loader of config/clustering.yaml (ConfigError names file and key).
ClusteringConfig loadClusteringConfig(const std::string& path);

}  // namespace cellsight
