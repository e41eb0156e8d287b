// PCL-heavy translation unit: keep PCL templates here, out of headers.
#include "cellsight/common/scan_cloud.hpp"

#include <pcl/features/normal_3d.h>
#include <pcl/filters/statistical_outlier_removal.h>
#include <pcl/io/pcd_io.h>
#include <pcl/console/print.h>
#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/io/ply_io.h>
#include <pcl/point_types.h>

#include <algorithm>
#include <cstdio>
#include <stdexcept>

#include "cellsight/common/errors.hpp"
#include "cellsight/common/pcl_cloud.hpp"

namespace cellsight {

namespace {
using PointT = pcl::PointXYZINormal;

pcl::PointCloud<PointT>::Ptr toPcl(const ScanCloud& c) {
  auto out = toPclXyzi<PointT>(c);
  for (size_t i = 0; i < c.size(); ++i) {
    PointT& p = (*out)[i];
    const bool has = i < c.normals.size();
    p.normal_x = has ? c.normals[i].x() : 0.f;
    p.normal_y = has ? c.normals[i].y() : 0.f;
    p.normal_z = has ? c.normals[i].z() : 0.f;
  }
  return out;
}

ScanCloud fromPcl(const pcl::PointCloud<PointT>& pc, const std::string& frame, bool normals) {
  ScanCloud c;
  c.frame_id = frame;
  for (const auto& p : pc) {
    c.append({p.x, p.y, p.z}, p.intensity);
    if (normals) c.normals.emplace_back(p.normal_x, p.normal_y, p.normal_z);
  }
  return c;
}
}  // namespace

ScanCloud statisticalOutlierRemoval(const ScanCloud& in, int k, double std_mul) {
  if (in.size() <= static_cast<size_t>(k)) return in;
  pcl::StatisticalOutlierRemoval<PointT> sor;
  sor.setInputCloud(toPcl(in));
  sor.setMeanK(k);
  sor.setStddevMulThresh(std_mul);
  pcl::PointCloud<PointT> out;
  sor.filter(out);
  return fromPcl(out, in.frame_id, !in.normals.empty());
}

ScanCloud cropBox(const ScanCloud& in, const Eigen::AlignedBox3f& box) {
  ScanCloud out;
  out.frame_id = in.frame_id;
  for (size_t i = 0; i < in.size(); ++i) {
    if (!box.contains(in.points[i])) continue;
    out.append(in.points[i], in.intensity[i]);
    if (!in.normals.empty()) out.normals.push_back(in.normals[i]);
  }
  return out;
}

size_t removeNonFinite(ScanCloud& c) {
  ScanCloud out;
  out.frame_id = c.frame_id;
  for (size_t i = 0; i < c.size(); ++i) {
    if (!c.points[i].allFinite()) continue;
    out.append(c.points[i], i < c.intensity.size() ? c.intensity[i] : 0.f);
    if (!c.normals.empty()) out.normals.push_back(c.normals[i]);
  }
  const size_t removed = c.size() - out.size();
  c = std::move(out);
  return removed;
}

double medianPointSpacing(const ScanCloud& cloud, size_t samples) {
  if (cloud.size() < 2) return 0.0;
  auto pc = toPclXyzi<pcl::PointXYZI>(cloud);
  pcl::KdTreeFLANN<pcl::PointXYZI> tree;
  tree.setInputCloud(pc);
  const size_t n = std::min(samples, cloud.size());
  std::vector<double> d;
  d.reserve(n);
  std::vector<int> idx(2);
  std::vector<float> sq(2);
  for (size_t k = 0; k < n; ++k) {
    const size_t i = k * cloud.size() / n;
    if (tree.nearestKSearch((*pc)[i], 2, idx, sq) == 2 && sq[1] > 0) d.push_back(std::sqrt(sq[1]));
  }
  if (d.empty()) return 0.0;
  std::nth_element(d.begin(), d.begin() + d.size() / 2, d.end());
  return d[d.size() / 2];
}

void estimateNormals(ScanCloud& cloud, int k, const Eigen::Vector3f& viewpoint) {
  auto pc = toPcl(cloud);
  pcl::NormalEstimation<PointT, pcl::Normal> ne;
  ne.setInputCloud(pc);
  ne.setKSearch(k);
  ne.setViewPoint(viewpoint.x(), viewpoint.y(), viewpoint.z());
  pcl::PointCloud<pcl::Normal> normals;
  ne.compute(normals);
  cloud.normals.resize(cloud.size());
  for (size_t i = 0; i < cloud.size(); ++i) {
    cloud.normals[i] = Eigen::Vector3f(normals[i].normal_x, normals[i].normal_y, normals[i].normal_z);
  }
}

void saveCloud(const std::string& path, const ScanCloud& cloud) {
  const auto pc = toPcl(cloud);
  const std::string tmp = path + ".tmp";
  int rc = -1;
  if (path.size() > 4 && path.substr(path.size() - 4) == ".ply") {
    pcl::PLYWriter writer;
    rc = writer.write(tmp, *pc, true, false);  // binary, no camera element
  } else if (path.size() > 4 && path.substr(path.size() - 4) == ".pcd") {
    rc = pcl::io::savePCDFileBinary(tmp, *pc);
  } else {
    throw std::runtime_error(path + ": cloud files must end in .ply or .pcd");
  }
  if (rc != 0 || std::rename(tmp.c_str(), path.c_str()) != 0) {
    std::remove(tmp.c_str());
    throw std::runtime_error(path + ": cannot write the cloud");
  }
}

ScanCloud loadCloud(const std::string& path) {
  pcl::PointCloud<PointT> pc;
  int rc = -1;
  // PCL warns for every field a file lacks (intensity, normals): not the user's problem; its
  // errors still print
  const pcl::console::VERBOSITY_LEVEL level = pcl::console::getVerbosityLevel();
  pcl::console::setVerbosityLevel(pcl::console::L_ERROR);
  struct Restore {
    pcl::console::VERBOSITY_LEVEL l;
    ~Restore() { pcl::console::setVerbosityLevel(l); }
  } restore{level};
  if (path.size() > 4 && path.substr(path.size() - 4) == ".ply") {
    rc = pcl::io::loadPLYFile(path, pc);
  } else if (path.size() > 4 && path.substr(path.size() - 4) == ".pcd") {
    rc = pcl::io::loadPCDFile(path, pc);
  } else {
    throw ConfigError(path + ": cloud files must end in .ply or .pcd");
  }
  if (rc < 0) throw ConfigError(path + ": cannot read the cloud (missing or corrupt)");
  ScanCloud c = fromPcl(pc, "base_link", true);
  bool any_normal = false;
  for (const auto& n : c.normals) any_normal = any_normal || n.squaredNorm() > 0;
  if (!any_normal) c.normals.clear();
  removeNonFinite(c);
  return c;
}

}  // namespace cellsight
