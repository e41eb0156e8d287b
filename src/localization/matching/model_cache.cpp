// The model-preparation cache: a prepared model (ModelIndex) as one flat binary file, keyed by
// the model's geometry and the settings that shape its preparation. The trees and the ray
// caster are rebuilt on load (fast); everything else is stored.
#include <cstdio>
#include <fstream>
#include <sstream>

#include "cellsight/common/binary_io.hpp"
#include "cellsight/common/file_io.hpp"
#include "matching_internal.hpp"

namespace cellsight {

using namespace matching_detail;

namespace {

// Bump when the preparation (sampling, normals, PPF table, field, grids) changes what it builds.
constexpr uint32_t kCacheVersion = 1;
constexpr uint32_t kMagic = 0x494d5343;  // "CSMI"

void writeCloud(BinaryWriter& w, const ScanCloud& c) {
  w.vec(c.points);
  w.vec(c.normals);
  w.vec(c.intensity);
  w.str(c.frame_id);
}

ScanCloud readCloud(BinaryReader& r) {
  ScanCloud c;
  c.points = r.vec<Eigen::Vector3f>();
  c.normals = r.vec<Eigen::Vector3f>();
  c.intensity = r.vec<float>();
  c.frame_id = r.str();
  if (!c.normals.empty() && c.normals.size() != c.points.size()) throw std::runtime_error("cloud record: inconsistent");
  return c;
}

template <typename T>
uint64_t hashVec(const std::vector<T>& v, uint64_t h) {
  return v.empty() ? h : fnv1a64(v.data(), v.size() * sizeof(T), h);
}

}  // namespace

std::string ModelMatcher::cacheFile(const ModelEntry& e, const std::string& id) const {
  const MatchingConfig& c = config_;
  uint64_t h = fnv1a64(&kCacheVersion, sizeof(kCacheVersion));
  h = fnv1a64(id.data(), id.size(), h);
  h = hashVec(e.mesh.vertices, h);
  h = hashVec(e.mesh.faces, h);
  h = hashVec(e.source_cloud.points, h);
  h = hashVec(e.source_cloud.normals, h);
  h = fnv1a64(e.sensor.data(), sizeof(float) * 3, h);
  std::ostringstream settings;
  settings.precision(17);
  settings << c.voxel << ' ' << c.normal_radius << ' ' << c.feature_radius << ' ' << c.coarse << ' ' << c.ppf_sampling
           << ' ' << c.ppf_distance_step << ' ' << c.ppf_angle_bins << ' ' << c.ppf_max_bucket << ' ' << c.icp_spacing
           << ' ' << c.inlier_distance << ' ' << c.icp_mesh_polish << ' ' << c.closest_point_grid << ' ' << c.fitness_radius
           << ' ' << c.descriptor;  // learned: no FPFH stored (its descriptors are computed at load)
  const std::string s = settings.str();
  h = fnv1a64(s.data(), s.size(), h);
  char name[32];
  std::snprintf(name, sizeof(name), "%016llx", static_cast<unsigned long long>(h));
  return c.model_cache_dir + "/" + id + "_" + name + ".bin";
}

void ModelMatcher::saveIndex(const std::string& file, const ModelIndex& m) const {
  BinaryWriter w;
  w.pod(kMagic);
  w.pod(kCacheVersion);
  w.str(m.id);
  w.pod<uint8_t>(m.has_mesh);
  writeCloud(w, *m.coarse);
  writeCloud(w, *m.fine);
  writeCloud(w, m.ppf_cloud);
  w.pod(m.ppf.dist_step);
  w.pod(m.ppf.angle_bins);
  w.vec(m.ppf.entries);
  w.vec(m.ppf.offset);
  w.vec(m.ppf.keys);
  w.vec(m.fpfh);
  w.vec(m.fpfh_valid);
  w.pod(m.field.origin);
  w.pod(m.field.cell);
  w.pod(m.field.dims);
  w.vec(m.field.nearest);
  w.pod<uint8_t>(!m.closest.empty());
  if (!m.closest.empty()) m.closest.write(w);
  w.vec(m.faces.group);
  w.pod<uint64_t>(m.faces.groups.size());
  for (const auto& g : m.faces.groups) {
    w.pod(g.normal);
    w.vec(g.creases);
    w.vec(g.crease_bounds);
  }
  w.pod(m.centroid);
  w.pod(m.diameter);
  w.vec(m.extremes);
  makeDirs(config_.model_cache_dir);
  writeFileAtomic(file, w.bytes());
}

bool ModelMatcher::loadIndex(const std::string& file, const ModelEntry& e, ModelIndex& m) const {
  std::ifstream in(file, std::ios::binary);
  if (!in) return false;
  const std::string bytes((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  try {
    BinaryReader r(bytes);
    if (r.pod<uint32_t>() != kMagic || r.pod<uint32_t>() != kCacheVersion) return false;
    if (r.str() != m.id) return false;
    m.has_mesh = r.pod<uint8_t>() != 0;
    m.coarse = std::make_shared<ScanCloud>(readCloud(r));
    m.fine = std::make_shared<ScanCloud>(readCloud(r));
    m.ppf_cloud = readCloud(r);
    m.ppf.dist_step = r.pod<float>();
    m.ppf.angle_bins = r.pod<int>();
    m.ppf.entries = r.vec<PpfTable::Entry>();
    m.ppf.offset = r.vec<uint32_t>();
    m.ppf.keys = r.vec<uint64_t>();
    if (m.ppf.angle_bins > 0) m.ppf.angles = AngleBins(m.ppf.angle_bins);
    m.fpfh = r.vec<Fpfh>();
    m.fpfh_valid = r.vec<int>();
    m.field.origin = r.pod<Vec3>();
    m.field.cell = r.pod<float>();
    m.field.dims = r.pod<Eigen::Vector3i>();
    m.field.nearest = r.vec<int32_t>();
    if (r.pod<uint8_t>()) m.closest = ClosestPointGrid::read(r);
    m.faces.group = r.vec<int>();
    const uint64_t groups = r.pod<uint64_t>();
    if (groups > bytes.size()) return false;
    m.faces.groups.resize(static_cast<size_t>(groups));
    for (auto& g : m.faces.groups) {
      g.normal = r.pod<Eigen::Vector3d>();
      g.creases = r.vec<std::pair<Eigen::Vector3d, Eigen::Vector3d>>();
      g.crease_bounds = r.vec<std::pair<Eigen::Vector3d, double>>();
    }
    m.centroid = r.pod<Eigen::Vector3d>();
    m.diameter = r.pod<float>();
    m.extremes = r.vec<Eigen::Vector3f>();
    if (!r.atEnd()) return false;
    // consistency: indices that the matcher follows without checks
    const Eigen::Vector3i D = m.field.dims;
    if ((D.array() < 0).any() || m.field.nearest.size() != static_cast<size_t>(D.x()) * D.y() * D.z()) return false;
    for (int32_t k : m.field.nearest)
      if (k >= static_cast<int32_t>(m.fine->size())) return false;
    for (int k : m.fpfh_valid)
      if (k < 0 || static_cast<size_t>(k) >= m.fpfh.size()) return false;
    for (const auto& en : m.ppf.entries)
      if (en.cell < 0 || static_cast<size_t>(en.cell) >= m.ppf_cloud.size() * static_cast<size_t>(std::max(1, m.ppf.angle_bins)))
        return false;
    for (uint32_t o : m.ppf.offset)
      if (o > m.ppf.entries.size()) return false;
    if (!m.ppf.keys.empty() && m.ppf.keys.size() != m.ppf.entries.size()) return false;
    if (m.has_mesh && !m.faces.group.empty() && m.faces.group.size() != e.mesh.faces.size()) return false;
    for (int g : m.faces.group)
      if (g >= static_cast<int>(m.faces.groups.size())) return false;
  } catch (const std::exception&) {
    return false;  // truncated or foreign: prepared again and overwritten
  }
  return true;
}

}  // namespace cellsight
