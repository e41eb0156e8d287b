// Open3D's registration on our clouds (Open3D stays inside open3d_registration.cpp): fast global
// registration (Zhou, Park, Koltun 2016) as the second coarse matcher, and Open3D's own RANSAC
// as a peer in the benchmark. Source = model, target = scene; the result maps model → scene.
#pragma once
#include <Eigen/Geometry>
#include <vector>

#include "cellsight/localization/model_library.hpp"

namespace cellsight {

struct FgrOptions {
  double max_correspondence_distance = 0.003;  ///< m, absolute
  int iterations = 64;
  double tuple_scale = 0.95;
  int max_tuples = 1000;
  int seed = 1;
};

Eigen::Isometry3d fastGlobalRegistration(const std::vector<Eigen::Vector3f>& model, const std::vector<Fpfh>& model_features,
                                         const std::vector<Eigen::Vector3f>& scene, const std::vector<Fpfh>& scene_features,
                                         const FgrOptions& options);

/// The same with any per-point features (rows: points; the learned descriptor).
Eigen::Isometry3d fastGlobalRegistration(const std::vector<Eigen::Vector3f>& model, const Eigen::MatrixXf& model_features,
                                         const std::vector<Eigen::Vector3f>& scene, const Eigen::MatrixXf& scene_features,
                                         const FgrOptions& options);

struct Open3dRansacOptions {
  double max_correspondence_distance = 0.003;
  bool mutual_filter = true;
  int max_iterations = 100000;
  double confidence = 0.999;
  double edge_similarity = 0.9;
};

/// Open3D RegistrationRANSACBasedOnFeatureMatching with its edge-length and distance checkers.
Eigen::Isometry3d open3dRansac(const std::vector<Eigen::Vector3f>& model, const std::vector<Fpfh>& model_features,
                               const std::vector<Eigen::Vector3f>& scene, const std::vector<Fpfh>& scene_features,
                               const Open3dRansacOptions& options);

}  // namespace cellsight
