// The only translation unit that includes Open3D.
#include <open3d/geometry/PointCloud.h>
#include <open3d/pipelines/registration/CorrespondenceChecker.h>
#include <open3d/pipelines/registration/FastGlobalRegistration.h>
#include <open3d/pipelines/registration/Feature.h>
#include <open3d/pipelines/registration/Registration.h>
#include <open3d/utility/Random.h>

#include "cellsight/localization/fgr.hpp"

namespace cellsight {
namespace {

namespace reg = open3d::pipelines::registration;

open3d::geometry::PointCloud toOpen3d(const std::vector<Eigen::Vector3f>& pts) {
  open3d::geometry::PointCloud c;
  c.points_.reserve(pts.size());
  for (const auto& p : pts) c.points_.push_back(p.cast<double>());
  return c;
}

reg::Feature toFeature(const std::vector<Fpfh>& f) {
  reg::Feature out;
  out.Resize(33, static_cast<int>(f.size()));
  for (size_t i = 0; i < f.size(); ++i) {
    for (int k = 0; k < 33; ++k) out.data_(k, static_cast<int>(i)) = f[i][k];
  }
  return out;
}

reg::Feature toFeature(const Eigen::MatrixXf& rows) {
  reg::Feature out;
  out.data_ = rows.transpose().cast<double>();
  return out;
}

Eigen::Isometry3d toIsometry(const Eigen::Matrix4d& M) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.matrix() = M;
  return T;
}


/// FGR on points and features already converted.
Eigen::Isometry3d fgr(const std::vector<Eigen::Vector3f>& model, const reg::Feature& model_features,
                      const std::vector<Eigen::Vector3f>& scene, const reg::Feature& scene_features, const FgrOptions& o) {
  open3d::utility::random::Seed(o.seed);
  reg::FastGlobalRegistrationOption opt(1.4, true, true, o.max_correspondence_distance, o.iterations, o.tuple_scale,
                                        o.max_tuples, true);
  const auto r = reg::FastGlobalRegistrationBasedOnFeatureMatching(toOpen3d(model), toOpen3d(scene), model_features,
                                                                   scene_features, opt);
  return toIsometry(r.transformation_);
}

}  // namespace

Eigen::Isometry3d fastGlobalRegistration(const std::vector<Eigen::Vector3f>& model, const std::vector<Fpfh>& model_features,
                                         const std::vector<Eigen::Vector3f>& scene, const std::vector<Fpfh>& scene_features,
                                         const FgrOptions& o) {
  if (model.size() < 3 || scene.size() < 3) return Eigen::Isometry3d::Identity();
  return fgr(model, toFeature(model_features), scene, toFeature(scene_features), o);
}

Eigen::Isometry3d fastGlobalRegistration(const std::vector<Eigen::Vector3f>& model, const Eigen::MatrixXf& model_features,
                                         const std::vector<Eigen::Vector3f>& scene, const Eigen::MatrixXf& scene_features,
                                         const FgrOptions& o) {
  if (model.size() < 3 || scene.size() < 3) return Eigen::Isometry3d::Identity();
  if (model_features.rows() != static_cast<Eigen::Index>(model.size()) ||
      scene_features.rows() != static_cast<Eigen::Index>(scene.size()) || model_features.cols() != scene_features.cols())
    throw std::invalid_argument("fastGlobalRegistration: one feature row per point, the same length on both sides");
  return fgr(model, toFeature(model_features), scene, toFeature(scene_features), o);
}

Eigen::Isometry3d open3dRansac(const std::vector<Eigen::Vector3f>& model, const std::vector<Fpfh>& model_features,
                               const std::vector<Eigen::Vector3f>& scene, const std::vector<Fpfh>& scene_features,
                               const Open3dRansacOptions& o) {
  if (model.size() < 3 || scene.size() < 3) return Eigen::Isometry3d::Identity();
  open3d::utility::random::Seed(1);
  reg::CorrespondenceCheckerBasedOnEdgeLength edge(o.edge_similarity);
  reg::CorrespondenceCheckerBasedOnDistance dist(o.max_correspondence_distance);
  const auto r = reg::RegistrationRANSACBasedOnFeatureMatching(
      toOpen3d(model), toOpen3d(scene), toFeature(model_features), toFeature(scene_features), o.mutual_filter,
      o.max_correspondence_distance, reg::TransformationEstimationPointToPoint(false), 3, {edge, dist},
      reg::RANSACConvergenceCriteria(o.max_iterations, o.confidence));
  return toIsometry(r.transformation_);
}

}  // namespace cellsight
