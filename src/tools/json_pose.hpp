// A pose as the project's JSON files write it ({xyz: [x, y, z], quat: [x, y, z, w]}: frames.json,
// frames_truth.jsonl, detections_raw.json), read back by the evaluation tools.
#pragma once
#include <Eigen/Geometry>
#include <nlohmann/json.hpp>

namespace cellsight_tools {

inline Eigen::Isometry3d poseFromJson(const nlohmann::json& d) {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(d.at("xyz")[0], d.at("xyz")[1], d.at("xyz")[2]);
  T.linear() = Eigen::Quaterniond(d.at("quat")[3], d.at("quat")[0], d.at("quat")[1], d.at("quat")[2])
                   .normalized()
                   .toRotationMatrix();
  return T;
}

}  // namespace cellsight_tools
