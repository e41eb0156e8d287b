// ModelMatcher: its construction and the per-model index built once (clouds with scan-like
// normals, descriptors or PPF table, distance field, ray caster, flat faces, rests). The pairs
// are matched in pair_matching.cpp, locate() runs in locate.cpp.
#include <pcl/features/normal_3d.h>
#include <pcl/search/kdtree.h>

#include <algorithm>
#include <cmath>
#include <stdexcept>

#include "matching_internal.hpp"

namespace cellsight {
namespace matching_detail {
namespace {

/// Flat faces smaller than this are not laid onto planar clusters: 25 coarse cells.
float patchMinArea(const MatchingConfig& cfg) { return static_cast<float>(25 * cfg.voxel * cfg.voxel); }

}  // namespace
}  // namespace matching_detail

using namespace matching_detail;  // the stages and their data (matching_internal.hpp)

ModelMatcher::ModelMatcher(std::shared_ptr<const ModelLibrary> library, const MatchingConfig& config)
    : library_(std::move(library)), config_(config) {
  if (!library_) throw std::invalid_argument("ModelMatcher: no model library");
  if (config_.coarse != "ppf" && config_.coarse != "ransac" && config_.coarse != "fgr") {
    throw std::invalid_argument("ModelMatcher: coarse must be 'ppf', 'ransac' or 'fgr' (got '" + config_.coarse + "')");
  }
  if (config_.scene_search != "grid" && config_.scene_search != "kdtree") {
    throw std::invalid_argument("ModelMatcher: scene_search must be 'grid' or 'kdtree' (got '" + config_.scene_search + "')");
  }
  if (!(config_.turned_rmse_ratio > 0 && config_.turned_rmse_ratio <= 1)) {
    throw std::invalid_argument("ModelMatcher: turned_rmse_ratio must be in (0, 1] (got " +
                                std::to_string(config_.turned_rmse_ratio) + ")");
  }
  if (!(config_.ambiguous_score_ratio >= 0 && config_.ambiguous_score_ratio <= 1)) {
    throw std::invalid_argument("ModelMatcher: ambiguous_score_ratio must be in [0, 1] (got " +
                                std::to_string(config_.ambiguous_score_ratio) + ")");
  }
  if (config_.threads <= 0) config_.threads = std::max(1u, std::thread::hardware_concurrency());
  if (config_.descriptor == "learned" && config_.coarse != "ppf") {
    try {
      learned_ = std::make_shared<const LearnedDescriptor>(LearnedDescriptor::load(config_.learned_model, config_.learned_dims));
      LearnedDescriptor::setThreads(1);  // the matcher runs its pairs in parallel itself
    } catch (const DescriptorModelError& e) {
      if (!config_.learned_fallback) throw;
      fallback_warning_ = std::string(e.what()) + "; descriptor: fpfh is used instead (learned_fallback)";
      config_.descriptor = "fpfh";
    }
  }
}

ModelMatcher::~ModelMatcher() = default;

void ModelMatcher::addLearned(ModelIndex& m) const {
  if (!learned_) return;
  m.learned.clear();
  for (const Eigen::Matrix3f& R : descriptorTurns(config_.learned_rotations)) {
    std::vector<Vec3> p(m.coarse->size()), n(m.coarse->size());
    for (size_t i = 0; i < p.size(); ++i) {
      p[i] = R * m.coarse->points[i];
      n[i] = R * m.coarse->normals[i];
    }
    m.learned.push_back(learned_->compute(p, n, config_.learned_scale));
  }
}

std::shared_ptr<const ModelMatcher::ModelIndex> ModelMatcher::index(const std::string& id) const {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = indices_.find(id);
    if (it != indices_.end()) return it->second;
  }
  const ModelEntry& e = library_->model(id);
  auto m = std::make_shared<ModelIndex>();
  m->id = id;
  m->info = e.info;
  const std::string cache = config_.model_cache_dir.empty() ? std::string() : cacheFile(e, id);
  if (!cache.empty() && loadIndex(cache, e, *m)) {
    // stored: everything but the search trees and the ray caster, rebuilt here
    if (!m->fpfh_valid.empty()) {
      std::vector<Fpfh> valid;
      for (int i : m->fpfh_valid) valid.push_back(m->fpfh[static_cast<size_t>(i)]);
      m->fpfh_tree.setInputCloud(toPclFpfh(valid));
    }
    m->fine_tree.setInputCloud(toXyz(m->fine->points));
    if (m->has_mesh) m->caster.addMesh(e.mesh, Eigen::Isometry3d::Identity());
    m->caster.commit();
    if (m->has_mesh) m->patches = facePatches(e.mesh, m->faces, patchMinArea(config_));
    addRests(*m);
    addLearned(*m);
    std::lock_guard<std::mutex> lock(mutex_);
    return indices_.emplace(id, m).first->second;
  }
  m->fine = library_->cloud(id, config_.icp_spacing);
  {
    // Descriptors see the model as a scan sees it: PCA normals over normal_radius (not the
    // mesh's sharp face normals), turned outwards; computed on the coarse cloud like the scene's.
    auto coarse = std::make_shared<ScanCloud>(*library_->cloud(id, config_.voxel));
    auto pts = toXyz(coarse->points);
    pcl::NormalEstimation<pcl::PointXYZ, pcl::Normal> ne;
    ne.setInputCloud(pts);
    ne.setSearchSurface(toXyz(m->fine->points));
    ne.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
    ne.setRadiusSearch(config_.normal_radius);
    pcl::PointCloud<pcl::Normal> normals;
    ne.compute(normals);
    for (size_t i = 0; i < coarse->size(); ++i) {
      Vec3 n = normals[i].getNormalVector3fMap();
      if (!n.allFinite() || n.norm() < 0.5f) continue;
      n.normalize();
      coarse->normals[i] = n.dot(coarse->normals[i]) < 0 ? -n : n;
    }
    m->coarse = coarse;
  }
  if (config_.coarse == "ppf") {
    m->ppf_cloud = thinned(*m->coarse, config_.ppf_sampling);
    m->ppf = buildPpf(m->ppf_cloud, static_cast<float>(config_.ppf_distance_step), config_.ppf_angle_bins,
                      static_cast<size_t>(config_.ppf_max_bucket));
  } else if (config_.descriptor == "learned") {
    addLearned(*m);
  } else {
    m->fpfh = computeFpfh(*m->coarse, config_.feature_radius);
    std::vector<Fpfh> valid;
    for (size_t i = 0; i < m->fpfh.size(); ++i) {
      if (!validFpfh(m->fpfh[i])) continue;
      m->fpfh_valid.push_back(static_cast<int>(i));
      valid.push_back(m->fpfh[i]);
    }
    if (!valid.empty()) m->fpfh_tree.setInputCloud(toPclFpfh(valid));
  }
  m->fine_tree.setInputCloud(toXyz(m->fine->points));
  // the surface centroid: exact from the mesh (a mean of the random fine samples is off by
  // ~R/sqrt(3N), 0.08 mm on the 25 mm sphere, which turns into pose error wherever a symmetry
  // leaves the rotation free); the mean of the points for a cloud model
  if (!e.mesh.faces.empty() && e.mesh.area() > 0) {
    m->centroid = e.mesh.surfaceCentroid();
  } else {
    for (const auto& p : m->fine->points) m->centroid += p.cast<double>();
    if (!m->fine->points.empty()) m->centroid /= static_cast<double>(m->fine->size());
  }
  m->diameter = e.bounds.diagonal().norm();
  if (!e.mesh.faces.empty()) {
    for (const auto& v : e.mesh.vertices) m->extremes.push_back(v.cast<float>());
  } else {
    m->extremes = m->coarse->points;
  }
  // distance field: cells of ≈ 1/3 of the coarse inlier distance (at most 4 M cells); each
  // fine point claims the cells within the margin whose centre it is nearest to
  const float margin = static_cast<float>(std::max(2 * config_.inlier_distance, 6 * config_.icp_spacing));
  const Eigen::Vector3f lo = e.bounds.min() - Vec3::Constant(margin), hi = e.bounds.max() + Vec3::Constant(margin);
  const Eigen::Vector3f size = hi - lo;
  float cell = static_cast<float>(std::max(config_.icp_spacing, config_.inlier_distance / 3));
  cell = std::max(cell, std::cbrt(size.prod() / 4e6f));
  m->field.origin = lo;
  m->field.cell = cell;
  m->field.dims = (size / cell).array().ceil().cast<int>().max(1);
  const Eigen::Vector3i D = m->field.dims;
  m->field.nearest.assign(static_cast<size_t>(D.x()) * D.y() * D.z(), -1);
  std::vector<float> best(m->field.nearest.size(), margin * margin);
  const int r = static_cast<int>(std::ceil(margin / cell));
  for (size_t j = 0; j < m->fine->size(); ++j) {
    const Vec3& p = m->fine->points[j];
    const Eigen::Vector3i c = ((p - lo) / cell).array().floor().cast<int>();
    for (int z = std::max(0, c.z() - r); z <= std::min(D.z() - 1, c.z() + r); ++z) {
      for (int y = std::max(0, c.y() - r); y <= std::min(D.y() - 1, c.y() + r); ++y) {
        for (int x = std::max(0, c.x() - r); x <= std::min(D.x() - 1, c.x() + r); ++x) {
          const size_t k = (static_cast<size_t>(z) * D.y() + y) * D.x() + x;
          const float d2 = (lo + cell * Vec3(x + 0.5f, y + 0.5f, z + 0.5f) - p).squaredNorm();
          if (d2 < best[k]) {
            best[k] = d2;
            m->field.nearest[k] = static_cast<int32_t>(j);
          }
        }
      }
    }
  }
  m->has_mesh = !e.mesh.faces.empty();
  if (m->has_mesh) m->caster.addMesh(e.mesh, Eigen::Isometry3d::Identity());
  m->caster.commit();
  if (m->has_mesh) m->faces = planarFaces(e.mesh);
  if (m->has_mesh) m->patches = facePatches(e.mesh, m->faces, patchMinArea(config_));
  addRests(*m);
  if (m->has_mesh && config_.icp_mesh_polish && config_.closest_point_grid && e.mesh.faces.size() <= 5000) {
    const float dmin = static_cast<float>(std::max(3 * config_.icp_spacing, 0.5 * config_.fitness_radius));
    const float cell = static_cast<float>(std::max(2 * config_.icp_spacing, 0.001));
    // margin: the polish's smallest correspondence distance and a cell (farther points are
    // rare in the polish: the RayCaster answers them)
    m->closest = ClosestPointGrid(e.mesh, cell, dmin + cell);
  }
  if (!cache.empty()) {
    try {
      saveIndex(cache, *m);
    } catch (const std::exception&) {
      // an unwritable cache costs time on the next start, nothing else
    }
  }
  std::lock_guard<std::mutex> lock(mutex_);
  return indices_.emplace(id, m).first->second;
}

void ModelMatcher::prepare(const std::vector<std::string>& models_in) const {
  const std::vector<std::string> models = models_in.empty() ? library_->ids() : models_in;
  for (const auto& id : models) library_->model(id);
  for (const auto& id : models) index(id);
}

Eigen::Vector3d ModelMatcher::centroid(const std::string& model) const { return index(model)->centroid; }

}  // namespace cellsight
