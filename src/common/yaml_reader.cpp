#include "cellsight/common/yaml_reader.hpp"

#include <fstream>
#include <sstream>

namespace cellsight {

YAML::Node loadYamlFile(const std::string& path) {
  std::ifstream in(path);
  if (!in) throw ConfigError(path + ": cannot open file (does it exist and is it readable?)");
  try {
    YAML::Node node = YAML::Load(in);
    if (!node || node.IsNull()) throw ConfigError(path + ": file is empty");
    return node;
  } catch (const YAML::Exception& e) {
    throw ConfigError(path + ": YAML syntax error at line " + std::to_string(e.mark.line + 1) +
                      ", column " + std::to_string(e.mark.column + 1) + ": " + e.msg);
  }
}

YamlMap::YamlMap(const YAML::Node& node, std::string file, std::string path)
    : node_(node), file_(std::move(file)), path_(std::move(path)) {
  if (!node_.IsMap()) {
    throw ConfigError(file_ + ": " + (path_.empty() ? std::string("document") : path_) +
                      " must be a mapping of key: value");
  }
}

std::string YamlMap::where(const std::string& key) const {
  return file_ + ": " + (path_.empty() ? key : path_ + "." + key);
}

void YamlMap::fail(const std::string& key, const std::string& what) const {
  throw ConfigError(where(key) + ": " + what);
}

bool YamlMap::has(const std::string& key) const {
  used_.insert(key);
  return static_cast<bool>(node_[key]);
}

const YAML::Node& YamlMap::child(const std::string& key) const {
  used_.insert(key);
  YAML::Node c = node_[key];
  if (!c) fail(key, "required key is missing");
  keep_.push_back(c);
  return keep_.back();
}

const YAML::Node& YamlMap::raw(const std::string& key) const { return child(key); }

namespace {
template <typename T>
T convert(const YamlMap& m, const YAML::Node& n, const std::string& key, const char* type) {
  if (!n.IsScalar()) m.fail(key, std::string("expected a ") + type);
  try {
    return n.as<T>();
  } catch (const YAML::Exception&) {
    m.fail(key, std::string("expected a ") + type + ", got '" + n.Scalar() + "'");
  }
}
}  // namespace

double YamlMap::getDouble(const std::string& key) const {
  double v = convert<double>(*this, child(key), key, "number");
  if (!std::isfinite(v)) fail(key, "must be a finite number");
  return v;
}
double YamlMap::getDouble(const std::string& key, double fallback) const {
  return has(key) ? getDouble(key) : fallback;
}
int YamlMap::getInt(const std::string& key) const {
  return convert<int>(*this, child(key), key, "integer");
}
int YamlMap::getInt(const std::string& key, int fallback) const {
  return has(key) ? getInt(key) : fallback;
}
bool YamlMap::getBool(const std::string& key, bool fallback) const {
  return has(key) ? convert<bool>(*this, child(key), key, "boolean (true/false)") : fallback;
}
std::string YamlMap::getString(const std::string& key) const {
  return convert<std::string>(*this, child(key), key, "string");
}
std::string YamlMap::getString(const std::string& key, const std::string& fallback) const {
  return has(key) ? getString(key) : fallback;
}

std::vector<double> YamlMap::getDoubles(const std::string& key, size_t expected_size) const {
  const YAML::Node& n = child(key);
  if (!n.IsSequence()) fail(key, "expected a list of " + std::to_string(expected_size) + " numbers");
  if (expected_size != 0 && n.size() != expected_size) {
    fail(key, "expected " + std::to_string(expected_size) + " numbers, got " +
                  std::to_string(n.size()));
  }
  std::vector<double> out;
  for (const auto& e : n) {
    try {
      out.push_back(e.as<double>());
    } catch (const YAML::Exception&) {
      fail(key, "list element '" + (e.IsScalar() ? e.Scalar() : std::string("?")) +
                    "' is not a number");
    }
    if (!std::isfinite(out.back())) fail(key, "list elements must be finite numbers");
  }
  return out;
}

Eigen::Vector3d YamlMap::getVector3(const std::string& key) const {
  auto v = getDoubles(key, 3);
  return {v[0], v[1], v[2]};
}
Eigen::Vector3d YamlMap::getVector3(const std::string& key, const Eigen::Vector3d& fallback) const {
  return has(key) ? getVector3(key) : fallback;
}

YamlMap YamlMap::getMap(const std::string& key) const {
  return YamlMap(child(key), file_, path_.empty() ? key : path_ + "." + key);
}

std::vector<YamlMap> YamlMap::getMapList(const std::string& key) const {
  const YAML::Node& n = child(key);
  if (!n.IsSequence()) fail(key, "expected a list");
  std::vector<YamlMap> out;
  for (size_t i = 0; i < n.size(); ++i) {
    out.emplace_back(n[i], file_, (path_.empty() ? key : path_ + "." + key) + "[" +
                                      std::to_string(i) + "]");
  }
  return out;
}

Eigen::Isometry3d YamlMap::getPose(const std::string& key) const {
  YamlMap m = getMap(key);
  Eigen::Isometry3d pose = parsePose(m);
  m.finish();
  return pose;
}
Eigen::Isometry3d YamlMap::getPose(const std::string& key,
                                   const Eigen::Isometry3d& fallback) const {
  return has(key) ? getPose(key) : fallback;
}

void YamlMap::finish() const {
  for (const auto& kv : node_) {
    const std::string key = kv.first.as<std::string>();
    if (!used_.count(key)) fail(key, "unknown key (misspelt? see docs/interfaces.md)");
  }
}

Eigen::Isometry3d parsePose(const YamlMap& m) {
  Eigen::Isometry3d pose = Eigen::Isometry3d::Identity();
  pose.translation() = m.getVector3("xyz", Eigen::Vector3d::Zero());
  const bool has_rpy = m.has("rpy"), has_quat = m.has("quat");
  if (has_rpy && has_quat) m.fail("rpy", "give either rpy or quat, not both");
  if (has_rpy) {
    Eigen::Vector3d rpy = m.getVector3("rpy");
    // REP 103 fixed-axis roll, pitch, yaw: R = Rz(yaw) * Ry(pitch) * Rx(roll).
    pose.linear() = (Eigen::AngleAxisd(rpy.z(), Eigen::Vector3d::UnitZ()) *
                     Eigen::AngleAxisd(rpy.y(), Eigen::Vector3d::UnitY()) *
                     Eigen::AngleAxisd(rpy.x(), Eigen::Vector3d::UnitX()))
                        .toRotationMatrix();
  } else if (has_quat) {
    auto q = m.getDoubles("quat", 4);
    Eigen::Quaterniond quat(q[3], q[0], q[1], q[2]);
    if (std::abs(quat.norm() - 1.0) > 1e-3) {
      m.fail("quat", "quaternion [x, y, z, w] must have unit norm (got " +
                         std::to_string(quat.norm()) + ")");
    }
    pose.linear() = quat.normalized().toRotationMatrix();
  }
  return pose;
}

void emitPose(YAML::Emitter& out, const Eigen::Isometry3d& pose) {
  Eigen::Quaterniond q(pose.linear());
  out << YAML::Flow << YAML::BeginMap;
  out << YAML::Key << "xyz" << YAML::Value << YAML::Flow << YAML::BeginSeq
      << pose.translation().x() << pose.translation().y() << pose.translation().z()
      << YAML::EndSeq;
  out << YAML::Key << "quat" << YAML::Value << YAML::Flow << YAML::BeginSeq << q.x() << q.y()
      << q.z() << q.w() << YAML::EndSeq;
  out << YAML::EndMap;
}

}  // namespace cellsight
