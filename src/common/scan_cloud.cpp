// PCL-heavy translation unit: keep PCL templates here, out of headers.
#include "cellsight/common/scan_cloud.hpp"

#include <cstdlib>
#include <cstring>
#include <fstream>
#include <set>
#include <sstream>

#include "ply_header.hpp"

#include <pcl/common/centroid.h>
#include <pcl/common/eigen.h>
#include <pcl/features/normal_3d.h>
#include <pcl/filters/statistical_outlier_removal.h>
#include <pcl/io/pcd_io.h>
#include <pcl/console/print.h>
#include <pcl/kdtree/kdtree_flann.h>
#include <pcl/io/lzf.h>
#include <pcl/io/ply_io.h>
#include <pcl/point_types.h>

#include <algorithm>
#include <cmath>
#include <cstdio>
#include <limits>
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

constexpr double kSkip = std::numeric_limits<double>::quiet_NaN();

/// The median of value(tree, point) over up to `samples` points spread evenly through the cloud,
/// `tree` holding the whole cloud; points whose value is kSkip (NaN) are left out; 0 when all are.
template <class Value>
double medianOverSpreadPoints(const ScanCloud& cloud, size_t samples, Value&& value) {
  pcl::KdTreeFLANN<pcl::PointXYZI> tree;
  tree.setInputCloud(toPclXyzi<pcl::PointXYZI>(cloud));
  const auto& pc = *tree.getInputCloud();
  const size_t n = std::min(samples, cloud.size());
  std::vector<double> v;
  v.reserve(n);
  for (size_t k = 0; k < n; ++k) {
    const double x = value(tree, pc[k * cloud.size() / n]);
    if (!std::isnan(x)) v.push_back(x);
  }
  if (v.empty()) return 0.0;
  std::nth_element(v.begin(), v.begin() + v.size() / 2, v.end());
  return v[v.size() / 2];
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
  pcl::Indices idx(2);
  std::vector<float> sq(2);
  return medianOverSpreadPoints(cloud, samples, [&](const pcl::KdTreeFLANN<pcl::PointXYZI>& tree, const pcl::PointXYZI& p) {
    return tree.nearestKSearch(p, 2, idx, sq) == 2 && sq[1] > 0 ? std::sqrt(sq[1]) : kSkip;
  });
}

double medianPlaneResidual(const ScanCloud& cloud, double radius, size_t samples) {
  if (!(radius > 0) || cloud.size() < 3) return 0.0;
  pcl::Indices idx;
  std::vector<float> sq;
  return medianOverSpreadPoints(cloud, samples, [&](const pcl::KdTreeFLANN<pcl::PointXYZI>& tree, const pcl::PointXYZI& p) {
    const int n = tree.radiusSearch(p, radius, idx, sq);
    if (n < 6) return kSkip;
    Eigen::Matrix3d cov = Eigen::Matrix3d::Zero();
    Eigen::Vector4d mean = Eigen::Vector4d::Zero();
    if (pcl::computeMeanAndCovarianceMatrix(*tree.getInputCloud(), idx, cov, mean) < 6) return kSkip;
    Eigen::Vector3d eigenvalues;  // ascending
    pcl::eigen33(cov, eigenvalues);
    // the plane is fitted to the same points: n - 3 degrees of freedom are left
    return std::sqrt(std::max(0.0, eigenvalues(0)) * n / (n - 3.0));
  });
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

namespace {

std::string readWholeFile(const std::string& path) {
  std::ifstream in(path, std::ios::binary);
  if (!in) throw ConfigError(path + ": cannot open the cloud file (missing or unreadable)");
  std::string data((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  if (data.empty()) throw ConfigError(path + ": the file is empty");
  return data;
}

bool endsWith(const std::string& s, const char* ext) {
  const size_t n = std::strlen(ext);
  return s.size() > n && s.compare(s.size() - n, n, ext) == 0;
}

/// A PCD header checked against the file: every field's size, type and count, a body that holds
/// what the header announces.
struct PcdHeader {
  std::vector<std::string> fields, types;
  std::vector<uint64_t> sizes, counts;
  uint64_t points = 0, point_bytes = 0, values_per_point = 0;
  std::string encoding;
  size_t body = 0;  ///< first byte after the DATA line
};

PcdHeader parsePcd(const std::string& path, const std::string& data) {
  std::istringstream hs(data.substr(0, std::min<size_t>(data.size(), 1u << 16)));
  std::string line;
  std::vector<std::string> fields, sizes, types, counts;
  uint64_t width = 0, height = 0, points = 0;
  std::string encoding;
  std::set<std::string> seen;
  size_t body = 0;
  auto number = [&](const std::string& key, const std::string& v) -> uint64_t {
    if (v.empty() || v.size() > 15 || v.find_first_not_of("0123456789") != std::string::npos)
      throw ConfigError(path + ": PCD " + key + " '" + v.substr(0, 40) + "' is not a count");
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
    // only the keys of the format (PCD v0.7), VERSION first, each once
    static const std::vector<std::string> kKeys = {"VERSION", "FIELDS", "COLUMNS", "SIZE", "TYPE", "COUNT",
                                                   "WIDTH", "HEIGHT", "VIEWPOINT", "POINTS", "DATA"};
    if (std::find(kKeys.begin(), kKeys.end(), key) == kKeys.end())
      throw ConfigError(path + ": PCD header line '" + line.substr(0, 40) + "' is not a PCD header key");
    if (!seen.insert(key).second) throw ConfigError(path + ": PCD header repeats " + key);
    if (seen.size() == 1 && key != "VERSION") throw ConfigError(path + ": PCD header does not start with VERSION");
    if (key == "FIELDS" || key == "COLUMNS") fields = values;
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
  PcdHeader h;
  h.fields = fields;
  h.types = types;
  for (size_t i = 0; i < fields.size(); ++i) {
    const uint64_t sz = number("SIZE", sizes[i]), n = number("COUNT", counts[i]);
    if (sz != 1 && sz != 2 && sz != 4 && sz != 8) throw ConfigError(path + ": PCD SIZE " + sizes[i] + " of field " + fields[i]);
    if (types[i] != "F" && types[i] != "I" && types[i] != "U") throw ConfigError(path + ": PCD TYPE " + types[i] + " of field " + fields[i]);
    if (types[i] == "F" && sz != 4 && sz != 8) throw ConfigError(path + ": PCD field " + fields[i] + " is F of " + sizes[i] + " bytes");
    if (n == 0 || n > 100000) throw ConfigError(path + ": PCD COUNT " + counts[i] + " of field " + fields[i]);
    h.sizes.push_back(sz);
    h.counts.push_back(n);
    h.point_bytes += sz * n;
    h.values_per_point += n;
  }
  if (width >= (1ull << 32) || height >= (1ull << 32)) throw ConfigError(path + ": PCD WIDTH or HEIGHT is too large");
  if (points == 0) points = width * height;
  if (width * height != points) throw ConfigError(path + ": PCD WIDTH x HEIGHT differs from POINTS");
  // no file holds more than 2^40 bytes of points: beyond that the products below could wrap
  if (h.point_bytes > 0 && points > (1ull << 40) / h.point_bytes)
    throw ConfigError(path + ": PCD claims " + std::to_string(points) + " points, more than any file holds");
  h.points = points;
  h.encoding = encoding;
  h.body = std::min(data.size(), body);
  const uint64_t rest = data.size() - h.body;
  if (encoding == "binary") {
    if (points > rest / std::max<uint64_t>(1, h.point_bytes))
      throw ConfigError(path + ": PCD claims " + std::to_string(points) + " points of " + std::to_string(h.point_bytes) +
                        " bytes, the body holds " + std::to_string(rest) + " bytes");
  } else if (encoding == "binary_compressed") {
    if (rest < 8) throw ConfigError(path + ": PCD compressed body is truncated");
    uint32_t compressed = 0, raw = 0;
    std::memcpy(&compressed, data.data() + h.body, 4);
    std::memcpy(&raw, data.data() + h.body + 4, 4);
    if (compressed > rest - 8 || raw != points * h.point_bytes)
      throw ConfigError(path + ": PCD compressed sizes disagree with the header or the file");
  } else if (encoding == "ascii") {
    if (points * h.values_per_point * 2 > rest + 1)  // a value takes a character and a separator
      throw ConfigError(path + ": PCD claims " + std::to_string(points) + " points, the body holds " +
                        std::to_string(rest) + " bytes of text");
  } else {
    throw ConfigError(path + ": PCD DATA '" + encoding.substr(0, 40) + "' is not ascii, binary or binary_compressed");
  }
  return h;
}

/// Value `v` of field `f` from a little-endian item of the field's type.
double pcdValue(const char* p, const std::string& type, uint64_t size) {
  if (type == "F") {
    if (size == 4) {
      float f;
      std::memcpy(&f, p, 4);
      return f;
    }
    double d;
    std::memcpy(&d, p, 8);
    return d;
  }
  if (type == "U") {
    uint64_t u = 0;
    std::memcpy(&u, p, size);
    return static_cast<double>(u);
  }
  switch (size) {
    case 1: return static_cast<int8_t>(*p);
    case 2: { int16_t i; std::memcpy(&i, p, 2); return i; }
    case 4: { int32_t i; std::memcpy(&i, p, 4); return i; }
    default: { int64_t i; std::memcpy(&i, p, 8); return static_cast<double>(i); }
  }
}

/// The columns loadCloud keeps, by field name: x y z (required), intensity, normals.
struct Columns {
  int x = -1, y = -1, z = -1, intensity = -1, nx = -1, ny = -1, nz = -1;
  static Columns of(const std::vector<std::string>& names, const std::string& path) {
    Columns c;
    for (size_t i = 0; i < names.size(); ++i) {
      const std::string& n = names[i];
      const int k = static_cast<int>(i);
      if (n == "x") c.x = k;
      else if (n == "y") c.y = k;
      else if (n == "z") c.z = k;
      else if (n == "intensity") c.intensity = k;
      else if (n == "normal_x" || n == "nx") c.nx = k;
      else if (n == "normal_y" || n == "ny") c.ny = k;
      else if (n == "normal_z" || n == "nz") c.nz = k;
    }
    if (c.x < 0 || c.y < 0 || c.z < 0) throw ConfigError(path + ": the cloud has no x, y and z fields");
    return c;
  }
  bool normals() const { return nx >= 0 && ny >= 0 && nz >= 0; }
  /// Appends the point whose value of column i is value(i).
  template <class F>
  void append(ScanCloud& c, const F& value) const {
    c.points.emplace_back(static_cast<float>(value(x)), static_cast<float>(value(y)), static_cast<float>(value(z)));
    c.intensity.push_back(intensity >= 0 ? static_cast<float>(value(intensity)) : 0.f);
    if (normals())
      c.normals.emplace_back(static_cast<float>(value(nx)), static_cast<float>(value(ny)), static_cast<float>(value(nz)));
  }
};

ScanCloud readPcd(const std::string& path, const std::string& data) {
  const PcdHeader h = parsePcd(path, data);
  const Columns col = Columns::of(h.fields, path);
  const size_t nf = h.fields.size();
  std::vector<uint64_t> offset(nf, 0);  // of each field's first value within a point
  for (size_t i = 1; i < nf; ++i) offset[i] = offset[i - 1] + h.sizes[i - 1] * h.counts[i - 1];
  ScanCloud c;
  c.points.reserve(h.points);
  if (h.encoding == "ascii") {
    // every value a number, each line as many values as the header lists, POINTS lines
    std::istringstream bs(data.substr(h.body));
    std::string line;
    std::vector<double> values(h.values_per_point);
    std::vector<size_t> first(nf, 0);  // index of each field's first value within a line
    for (size_t i = 1; i < nf; ++i) first[i] = first[i - 1] + h.counts[i - 1];
    uint64_t lines = 0;
    while (lines < h.points && std::getline(bs, line)) {
      if (!line.empty() && line.back() == '\r') line.pop_back();
      if (line.empty()) continue;
      std::istringstream ls(line);
      std::string tok;
      uint64_t n = 0;
      while (ls >> tok) {
        char* endp = nullptr;
        const double v = std::strtod(tok.c_str(), &endp);
        if (endp == tok.c_str() || *endp != '\0')
          throw ConfigError(path + ": PCD line " + std::to_string(lines + 1) + " of the body holds '" + tok.substr(0, 40) +
                            "', not a number");
        if (n < values.size()) values[n] = v;
        ++n;
      }
      if (n != h.values_per_point)
        throw ConfigError(path + ": PCD line " + std::to_string(lines + 1) + " of the body has " + std::to_string(n) +
                          " values, the header " + std::to_string(h.values_per_point));
      col.append(c, [&](int f) { return values[first[f]]; });
      ++lines;
    }
    if (lines < h.points)
      throw ConfigError(path + ": PCD claims " + std::to_string(h.points) + " points, the body holds " + std::to_string(lines));
  } else if (h.encoding == "binary") {
    const char* base = data.data() + h.body;  // parsePcd checked points x point_bytes fit
    for (uint64_t k = 0; k < h.points; ++k) {
      const char* p = base + k * h.point_bytes;
      col.append(c, [&](int f) { return pcdValue(p + offset[f], h.types[f], h.sizes[f]); });
    }
  } else {  // binary_compressed: LZF over the fields one after the other (all x, then all y, ...)
    uint32_t compressed = 0, raw = 0;
    std::memcpy(&compressed, data.data() + h.body, 4);
    std::memcpy(&raw, data.data() + h.body + 4, 4);
    std::vector<char> plain(raw);
    if (raw > 0 && pcl::lzfDecompress(data.data() + h.body + 8, compressed, plain.data(), raw) != raw)
      throw ConfigError(path + ": PCD compressed body does not decompress to the size its header gives");
    for (uint64_t k = 0; k < h.points; ++k) {
      col.append(c, [&](int f) {
        const uint64_t item = h.sizes[f] * h.counts[f];
        return pcdValue(plain.data() + offset[f] * h.points + k * item, h.types[f], h.sizes[f]);
      });
    }
  }
  return c;
}

ScanCloud readPlyCloud(const std::string& path, const std::string& data) {
  const ply::Header h = ply::parse(path, data);
  bool vertex = false;
  for (const auto& e : h.elements) vertex = vertex || (e.name == "vertex" && e.count > 0);
  if (!vertex) throw ConfigError(path + ": the PLY file has no vertices");
  const ply::Body body = ply::readBody(path, data, h);
  const Columns col = Columns::of(body.vertex_props, path);
  const size_t n = body.vertex_props.size();
  ScanCloud c;
  for (size_t k = 0; k < body.vertices.size() / n; ++k) {
    const double* v = &body.vertices[k * n];
    col.append(c, [&](int f) { return v[f]; });
  }
  return c;
}

}  // namespace

void checkCloudFile(const std::string& path) {
  const std::string data = readWholeFile(path);
  if (endsWith(path, ".ply")) {
    readPlyCloud(path, data);
  } else {
    readPcd(path, data);
  }
}

ScanCloud loadCloud(const std::string& path) {
  if (!endsWith(path, ".ply") && !endsWith(path, ".pcd"))
    throw ConfigError(path + ": cloud files must end in .ply or .pcd");
  const std::string data = readWholeFile(path);
  ScanCloud c = endsWith(path, ".ply") ? readPlyCloud(path, data) : readPcd(path, data);
  c.frame_id = "base_link";
  bool any_normal = false;
  for (const auto& n : c.normals) any_normal = any_normal || n.squaredNorm() > 0;
  if (!any_normal) c.normals.clear();
  removeNonFinite(c);
  return c;
}

ScanCloud loadCloudWithPcl(const std::string& path) {
  checkCloudFile(path);  // PCL's readers trust their headers
  pcl::PointCloud<PointT> pc;
  int rc = -1;
  const pcl::console::VERBOSITY_LEVEL level = pcl::console::getVerbosityLevel();
  pcl::console::setVerbosityLevel(pcl::console::L_ERROR);
  struct Restore {
    pcl::console::VERBOSITY_LEVEL l;
    ~Restore() { pcl::console::setVerbosityLevel(l); }
  } restore{level};
  if (endsWith(path, ".ply")) {
    rc = pcl::io::loadPLYFile(path, pc);
  } else if (endsWith(path, ".pcd")) {
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
