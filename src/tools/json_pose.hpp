// JSON of the tools: a pose as the project's JSON files write it ({xyz: [x, y, z], quat: [x, y, z,
// w]}: frames.json, frames_truth.jsonl, detections_raw.json, truth/placements.jsonl), read back by
// the evaluation tools; results written atomically; the median of their figures.
#pragma once
#include <Eigen/Geometry>
#include <algorithm>
#include <cmath>
#include <nlohmann/json.hpp>
#include <string>
#include <vector>

#include "cellsight/common/file_io.hpp"

namespace cellsight_tools {

/// Writes `j` (indented) to `path` atomically; nothing when `path` is empty.
inline void writeJson(const std::string& path, const nlohmann::json& j) {
  if (!path.empty()) cellsight::writeFileAtomic(path, j.dump(2) + "\n");
}

/// The median (NaN for none).
inline double median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  return v.size() % 2 ? v[v.size() / 2] : 0.5 * (v[v.size() / 2 - 1] + v[v.size() / 2]);
}

inline Eigen::Isometry3d poseFromJson(const nlohmann::json& d) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(d.at("xyz")[0], d.at("xyz")[1], d.at("xyz")[2]);
  T.linear() = Eigen::Quaterniond(d.at("quat")[3], d.at("quat")[0], d.at("quat")[1], d.at("quat")[2])
                   .normalized()
                   .toRotationMatrix();
  return T;
}

inline nlohmann::json poseToJson(const Eigen::Isometry3d& T) {
  const Eigen::Quaterniond q(T.linear());
  return {{"xyz", {T.translation().x(), T.translation().y(), T.translation().z()}}, {"quat", {q.x(), q.y(), q.z(), q.w()}}};
}

}  // namespace cellsight_tools
