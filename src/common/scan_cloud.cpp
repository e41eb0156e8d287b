// PCL-heavy translation unit: keep PCL templates here, out of headers.
#include "cellsight/common/scan_cloud.hpp"

#include <cstdlib>
#include <cstring>
#include <fstream>
#include <sstream>

#include "ply_header.hpp"

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

void checkCloudFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ConfigError(path + ": cannot open the cloud file (missing or unreadable)");
  const std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (data.empty()) throw ConfigError(path + ": the file is empty");
  if (path.size() > 4 && path.substr(path.size() - 4) == ".ply") {
    const ply::Header h = ply::parse(path, data);
    bool vertex = false;
    for (const auto& e : h.elements) vertex = vertex || (e.name == "vertex" && e.count > 0);
    if (!vertex) throw ConfigError(path + ": the PLY file has no vertices");
    return;
  }
  // PCD: the header's fields, sizes and counts agree, and the body holds what they announce
  std::istringstream hs(data.substr(0, std::min<size_t>(data.size(), 1u << 16)));
  std::string line;
  std::vector<std::string> fields, sizes, types, counts;
  uint64_t width = 0, height = 0, points = 0;
  std::string encoding;
  size_t body = 0;
  auto number = [&](const std::string& key, const std::string& v) -> uint64_t {
    if (v.empty() || v.size() > 15 || v.find_first_not_of("0123456789") != std::string::npos)
      throw ConfigError(path + ": PCD " + key + " '" + v + "' is not a count");
    return std::stoull(v);
  };
  while (std::getline(hs, line)) {
    body += line.size() + 1;
    if (!line.empty() && line.back() == '\r') line.pop_back();
    if (line.empty() || line[0] == '#') continue;
    std::istringstream ls(line);
    std::string key, v;
    ls >> key;
    std::vector<std::string> values;
    while (ls >> v) values.push_back(v);
    if (key == "FIELDS") fields = values;
    else if (key == "SIZE") sizes = values;
    else if (key == "TYPE") types = values;
    else if (key == "COUNT") counts = values;
    else if (key == "WIDTH") width = number(key, values.empty() ? "" : values[0]);
    else if (key == "HEIGHT") height = number(key, values.empty() ? "" : values[0]);
    else if (key == "POINTS") points = number(key, values.empty() ? "" : values[0]);
    else if (key == "DATA") {
      encoding = values.empty() ? "" : values[0];
      break;
    }
  }
  if (encoding.empty()) throw ConfigError(path + ": not a PCD file (no DATA line in its header)");
  if (counts.empty()) counts.assign(fields.size(), "1");
  if (fields.empty() || sizes.size() != fields.size() || types.size() != fields.size() || counts.size() != fields.size())
    throw ConfigError(path + ": PCD FIELDS, SIZE, TYPE and COUNT do not list the same number of fields");
  uint64_t point_bytes = 0, values_per_point = 0;
  for (size_t i = 0; i < fields.size(); ++i) {
    const uint64_t sz = number("SIZE", sizes[i]), n = number("COUNT", counts[i]);
    if (sz != 1 && sz != 2 && sz != 4 && sz != 8) throw ConfigError(path + ": PCD SIZE " + sizes[i] + " of field " + fields[i]);
    if (types[i] != "F" && types[i] != "I" && types[i] != "U") throw ConfigError(path + ": PCD TYPE " + types[i] + " of field " + fields[i]);
    if (n == 0 || n > 100000) throw ConfigError(path + ": PCD COUNT " + counts[i] + " of field " + fields[i]);
    point_bytes += sz * n;
    values_per_point += n;
  }
  if (points == 0) points = width * height;
  if (width * height != points) throw ConfigError(path + ": PCD WIDTH x HEIGHT differs from POINTS");
  const uint64_t rest = data.size() - std::min(data.size(), body);
  if (encoding == "binary") {
    if (points > rest / std::max<uint64_t>(1, point_bytes))
      throw ConfigError(path + ": PCD claims " + std::to_string(points) + " points of " + std::to_string(point_bytes) +
                        " bytes, the body holds " + std::to_string(rest) + " bytes");
  } else if (encoding == "binary_compressed") {
    if (rest < 8) throw ConfigError(path + ": PCD compressed body is truncated");
    uint32_t compressed = 0, raw = 0;
    std::memcpy(&compressed, data.data() + body, 4);
    std::memcpy(&raw, data.data() + body + 4, 4);
    if (compressed > rest - 8 || raw != points * point_bytes)
      throw ConfigError(path + ": PCD compressed sizes disagree with the header or the file");
  } else if (encoding == "ascii") {
    // every value a number (PCL reads text as zeros), at least POINTS lines of them
    std::istringstream bs(data.substr(body));
    uint64_t lines = 0;
    while (lines < points && std::getline(bs, line)) {
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (line.empty()) continue;
      std::istringstream ls(line);
      std::string tok;
      uint64_t n = 0;
      while (ls >> tok) {
        char* endp = nullptr;
        std::strtod(tok.c_str(), &endp);
        if (endp == tok.c_str() || *endp != '\0')
          throw ConfigError(path + ": PCD line " + std::to_string(lines + 1) + " of the body holds '" + tok + "', not a number");
        ++n;
      }
      if (n != values_per_point)
        throw ConfigError(path + ": PCD line " + std::to_string(lines + 1) + " of the body has " + std::to_string(n) +
                          " values, the header " + std::to_string(values_per_point));
      ++lines;
    }
    if (lines < points) throw ConfigError(path + ": PCD claims " + std::to_string(points) + " points, the body holds " + std::to_string(lines));
  } else {
    throw ConfigError(path + ": PCD DATA '" + encoding + "' is not ascii, binary or binary_compressed");
  }
}

ScanCloud loadCloud(const std::string& path) {
  if (path.size() > 4 && (path.substr(path.size() - 4) == ".ply" || path.substr(path.size() - 4) == ".pcd"))
    checkCloudFile(path);  // PCL's readers trust their headers
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
