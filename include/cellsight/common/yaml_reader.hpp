// Strict YAML reading: every key of a mapping must be known, every error names file and key path.
// Only translation units that parse configuration include this header (it pulls in yaml-cpp).
#pragma once
#include <yaml-cpp/yaml.h>

#include <Eigen/Geometry>
#include <set>
#include <string>
#include <vector>

#include "cellsight/common/errors.hpp"

namespace cellsight {

/// Loads a YAML file; throws ConfigError naming the file on a missing file or a syntax error.
YAML::Node loadYamlFile(const std::string& path);

/// A view of one YAML mapping that remembers which keys were read, so that unknown keys
/// (typos) are reported by finish() instead of being silently ignored.
class YamlMap {
 public:
  YamlMap(const YAML::Node& node, std::string file, std::string path = "");

  bool has(const std::string& key) const;
  double getDouble(const std::string& key) const;
  double getDouble(const std::string& key, double fallback) const;
  int getInt(const std::string& key) const;
  int getInt(const std::string& key, int fallback) const;
  bool getBool(const std::string& key, bool fallback) const;
  std::string getString(const std::string& key) const;
  std::string getString(const std::string& key, const std::string& fallback) const;
  std::vector<double> getDoubles(const std::string& key, size_t expected_size) const;
  Eigen::Vector3d getVector3(const std::string& key) const;
  Eigen::Vector3d getVector3(const std::string& key, const Eigen::Vector3d& fallback) const;
  /// A pose given as {xyz: [m], rpy: [rad]} or {xyz: [m], quat: [x, y, z, w]}.
  Eigen::Isometry3d getPose(const std::string& key) const;
  Eigen::Isometry3d getPose(const std::string& key, const Eigen::Isometry3d& fallback) const;
  YamlMap getMap(const std::string& key) const;
  /// Elements of a sequence of mappings.
  std::vector<YamlMap> getMapList(const std::string& key) const;
  const YAML::Node& raw(const std::string& key) const;

  /// Throws ConfigError listing any key that was never read.
  void finish() const;

  const std::string& file() const { return file_; }
  std::string where(const std::string& key) const;
  [[noreturn]] void fail(const std::string& key, const std::string& what) const;

 private:
  const YAML::Node& child(const std::string& key) const;
  YAML::Node node_;
  std::string file_;
  std::string path_;
  mutable std::set<std::string> used_;
  mutable std::vector<YAML::Node> keep_;
};

/// Parses a pose mapping ({xyz, rpy} or {xyz, quat}).
Eigen::Isometry3d parsePose(const YamlMap& map);

/// Writes a pose as a flow mapping {xyz: [...], quat: [...]} into an emitter.
void emitPose(YAML::Emitter& out, const Eigen::Isometry3d& pose);

}  // namespace cellsight
