// PCL-heavy translation unit (FPFH, voxel thinning).
#include "cellsight/localization/model_library.hpp"

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <pcl/features/fpfh.h>
#include <pcl/filters/uniform_sampling.h>
#include <pcl/filters/voxel_grid.h>
#include <pcl/point_types.h>
#include <pcl/search/kdtree.h>
#include <random>
#include <stdexcept>
#include <tuple>

#include "cellsight/common/errors.hpp"

namespace cellsight {

ScanCloud sampleMesh(const TriangleMesh& mesh, double spacing, uint64_t seed, CellSample keep) {
  if (!(spacing > 0)) throw std::invalid_argument("sampleMesh: spacing must be > 0");
  // Cumulative areas for area-weighted face choice; enough samples for ~4 per voxel face.
  std::vector<double> cum;
  double total = 0;
  for (const auto& f : mesh.faces) {
    total += 0.5 * (mesh.vertices[f[1]] - mesh.vertices[f[0]]).cross(mesh.vertices[f[2]] - mesh.vertices[f[0]]).norm();
    cum.push_back(total);
  }
  if (total <= 0) return ScanCloud();
  const size_t n = static_cast<size_t>(std::min(5e6, 4.0 * total / (spacing * spacing))) + 100;
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<double> U(0, 1);
  pcl::PointCloud<pcl::PointNormal>::Ptr dense(new pcl::PointCloud<pcl::PointNormal>);
  dense->reserve(n);
  for (size_t i = 0; i < n; ++i) {
    const size_t fi = static_cast<size_t>(std::lower_bound(cum.begin(), cum.end(), U(rng) * total) - cum.begin());
    const auto& f = mesh.faces[std::min(fi, mesh.faces.size() - 1)];
    double a = U(rng), b = U(rng);
    if (a + b > 1) {
      a = 1 - a;
      b = 1 - b;
    }
    const Eigen::Vector3f& A = mesh.vertices[f[0]];
    const Eigen::Vector3f p = A + static_cast<float>(a) * (mesh.vertices[f[1]] - A) + static_cast<float>(b) * (mesh.vertices[f[2]] - A);
    const Eigen::Vector3f nrm = (mesh.vertices[f[1]] - A).cross(mesh.vertices[f[2]] - A).normalized();
    pcl::PointNormal q;
    q.x = p.x();
    q.y = p.y();
    q.z = p.z();
    q.normal_x = nrm.x();
    q.normal_y = nrm.y();
    q.normal_z = nrm.z();
    dense->push_back(q);
  }
  // One sample per cell. Models keep the dense sample nearest the cell's centre (PCL
  // UniformSampling): every point lies on the surface with its face's normal. Cell centroids
  // (VoxelGrid) sit inside the solid at edges with blended normals, and edges are what fixes a
  // part's pose; they are what the clustering's voxel grid makes of a scan, though, so the
  // simulated single views keep them.
  pcl::PointCloud<pcl::PointNormal> thin;
  const float leaf = static_cast<float>(spacing);
  if (keep == CellSample::kCentroid) {
    pcl::VoxelGrid<pcl::PointNormal> vg;
    vg.setInputCloud(dense);
    vg.setLeafSize(leaf, leaf, leaf);
    vg.filter(thin);
  } else {
    pcl::UniformSampling<pcl::PointNormal> us;
    us.setInputCloud(dense);
    us.setRadiusSearch(spacing);
    us.filter(thin);
  }
  ScanCloud out;
  out.frame_id = "model";
  for (const auto& q : thin) {
    out.append({q.x, q.y, q.z}, 0.f);
    Eigen::Vector3f nrm(q.normal_x, q.normal_y, q.normal_z);
    out.normals.push_back(nrm.norm() > 1e-6f ? nrm.normalized() : Eigen::Vector3f::UnitZ());
  }
  return out;
}

std::vector<Fpfh> computeFpfh(const ScanCloud& c, double radius) {
  if (c.normals.size() != c.points.size()) throw std::invalid_argument("computeFpfh: the cloud needs normals");
  pcl::PointCloud<pcl::PointXYZ>::Ptr pts(new pcl::PointCloud<pcl::PointXYZ>);
  pcl::PointCloud<pcl::Normal>::Ptr nrm(new pcl::PointCloud<pcl::Normal>);
  for (size_t i = 0; i < c.size(); ++i) {
    pts->push_back(pcl::PointXYZ(c.points[i].x(), c.points[i].y(), c.points[i].z()));
    nrm->push_back(pcl::Normal(c.normals[i].x(), c.normals[i].y(), c.normals[i].z()));
  }
  pcl::FPFHEstimation<pcl::PointXYZ, pcl::Normal, pcl::FPFHSignature33> fe;
  fe.setInputCloud(pts);
  fe.setInputNormals(nrm);
  fe.setSearchMethod(pcl::make_shared<pcl::search::KdTree<pcl::PointXYZ>>());
  fe.setRadiusSearch(radius);
  pcl::PointCloud<pcl::FPFHSignature33> f;
  fe.compute(f);
  std::vector<Fpfh> out(f.size());
  for (size_t i = 0; i < f.size(); ++i) std::copy(f[i].histogram, f[i].histogram + 33, out[i].begin());
  return out;
}

ModelLibrary::ModelLibrary(const std::string& folder) {
  namespace fs = std::filesystem;
  std::error_code ec;
  fs::directory_iterator it(folder, ec), end;
  if (ec) throw ConfigError(folder + ": model folder cannot be opened");
  std::vector<std::string> ids;  // <id>/model.yaml (links followed), hidden entries skipped
  for (; !ec && it != end; it.increment(ec)) {
    const std::string name = it->path().filename().string();
    std::error_code exists_ec;
    if (name.empty() || name[0] == '.' || !fs::exists(fs::path(folder) / name / "model.yaml", exists_ec)) continue;
    ids.push_back(name);
  }
  if (ec) throw ConfigError(folder + ": model folder cannot be read: " + ec.message());
  // sorted: models load (and the first bad one is reported) in the same order on every file system
  std::sort(ids.begin(), ids.end());
  if (ids.empty()) throw ConfigError(folder + ": no <id>/model.yaml found");
  for (const auto& id : ids) {
    ModelEntry m;
    m.info = loadModelInfo(folder + "/" + id + "/model.yaml");
    if (m.info.id != id) {
      throw ConfigError(folder + "/" + id + "/model.yaml: id: '" + m.info.id + "' differs from its folder name '" + id + "'");
    }
    m.mesh = loadValidMesh(m.info.mesh_file);
    m.bounds = m.mesh.bounds();
    const Eigen::Vector3f s = m.bounds.sizes();
    if (s.minCoeff() < 0.02f * s.maxCoeff()) {
      m.warnings.push_back("nearly flat (" + std::to_string(s.minCoeff() * 1e3) + " mm thin): its pose about the plane normal is poorly constrained");
    }
    if (s.maxCoeff() < 0.005f) m.warnings.push_back("tiny (" + std::to_string(s.maxCoeff() * 1e3) + " mm): few scan points will fall on it");
    models_.emplace(id, std::move(m));
  }
}

void ModelLibrary::addCloudModel(const std::string& id, const ScanCloud& cloud, const Eigen::Vector3f& sensor) {
  if (models_.count(id)) throw std::invalid_argument("addCloudModel: model '" + id + "' exists already");
  ModelEntry m;
  m.info.id = id;
  for (const auto& p : cloud.points) {
    if (!p.allFinite()) continue;
    m.source_cloud.append(p, 0.f);
    m.bounds.extend(p);
  }
  if (m.source_cloud.size() < 10) {
    throw std::invalid_argument("addCloudModel: model '" + id + "' has " + std::to_string(m.source_cloud.size()) +
                                " finite points (at least 10 needed)");
  }
  m.source_cloud.frame_id = "model";
  m.sensor = sensor;
  models_.emplace(id, std::move(m));
}

void ModelLibrary::addMeshModel(const std::string& id, const TriangleMesh& mesh) {
  if (models_.count(id)) throw std::invalid_argument("addMeshModel: model '" + id + "' exists already");
  if (mesh.faces.empty()) throw std::invalid_argument("addMeshModel: model '" + id + "' has no faces");
  ModelEntry m;
  m.info.id = id;
  m.mesh = mesh;
  m.bounds = mesh.bounds();
  models_.emplace(id, std::move(m));
}

std::vector<std::string> ModelLibrary::ids() const {
  std::vector<std::string> out;
  for (const auto& kv : models_) out.push_back(kv.first);
  return out;
}

const ModelEntry& ModelLibrary::model(const std::string& id) const {
  auto it = models_.find(id);
  if (it == models_.end()) {
    std::string known;
    for (const auto& kv : models_) known += " " + kv.first;
    throw std::out_of_range("unknown model '" + id + "' (known:" + known + ")");
  }
  return it->second;
}

std::shared_ptr<const ScanCloud> ModelLibrary::cloud(const std::string& id, double resolution) const {
  const ModelEntry& m = model(id);
  const auto key = std::make_pair(id, std::lround(resolution * 1e7));
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = clouds_.find(key);
    if (it != clouds_.end()) return it->second;
  }
  std::shared_ptr<const ScanCloud> c;
  if (m.mesh.faces.empty()) {
    // a cloud model: voxel centroids at the resolution, normals from neighbours toward the sensor
    pcl::PointCloud<pcl::PointXYZ>::Ptr in(new pcl::PointCloud<pcl::PointXYZ>);
    for (const auto& p : m.source_cloud.points) in->push_back(pcl::PointXYZ(p.x(), p.y(), p.z()));
    pcl::VoxelGrid<pcl::PointXYZ> vg;
    vg.setInputCloud(in);
    const float leaf = static_cast<float>(resolution);
    vg.setLeafSize(leaf, leaf, leaf);
    pcl::PointCloud<pcl::PointXYZ> thin;
    vg.filter(thin);
    ScanCloud out;
    out.frame_id = "model";
    for (const auto& q : thin) out.append(q.getVector3fMap(), 0.f);
    estimateNormals(out, 12, m.sensor);
    c = std::make_shared<const ScanCloud>(std::move(out));
  } else {
    c = std::make_shared<const ScanCloud>(sampleMesh(m.mesh, resolution));
  }
  std::lock_guard<std::mutex> lock(mutex_);
  return clouds_.emplace(key, c).first->second;
}

std::shared_ptr<const std::vector<Fpfh>> ModelLibrary::descriptors(const std::string& id, double resolution,
                                                                   double radius) const {
  const auto key = std::make_tuple(id, std::lround(resolution * 1e7), std::lround(radius * 1e7));
  {
    std::lock_guard<std::mutex> lock(mutex_);
    auto it = fpfh_.find(key);
    if (it != fpfh_.end()) return it->second;
  }
  auto d = std::make_shared<const std::vector<Fpfh>>(computeFpfh(*cloud(id, resolution), radius));
  std::lock_guard<std::mutex> lock(mutex_);
  return fpfh_.emplace(key, d).first->second;
}

}  // namespace cellsight
