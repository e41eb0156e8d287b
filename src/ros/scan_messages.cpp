#include "cellsight_ros/scan_messages.hpp"

#include <sensor_msgs/image_encodings.h>

#include <algorithm>
#include <cctype>
#include <cmath>

#include "cellsight_ros/conversions.hpp"
#include "cellsight_ros/params.hpp"

namespace cellsight_ros {

namespace {
sensor_msgs::PointCloud2 pointsMsg(const std::vector<Eigen::Vector3f>& points, const std_msgs::Header& header) {
  cellsight::ScanCloud c;
  for (const auto& p : points) c.append(p, 0.f);
  sensor_msgs::PointCloud2 m = toCloudMsg(c, header.stamp);
  m.header.frame_id = header.frame_id;
  return m;
}
}  // namespace

cellsight::LineExtractionConfig lineConfigFor(const std::string& encoding, cellsight::LineExtractionConfig line) {
  namespace enc = sensor_msgs::image_encodings;
  if (encoding == enc::MONO8) {
    line.channel = -1;
  } else {
    if (line.channel < 0) line.channel = 0;  // red laser by default
    if (encoding == enc::BGR8) line.channel = 2 - line.channel;
  }
  return line;
}

cellsight::ClusterArray toClusterArrayMsg(const cellsight::ClusteringResult& r, const std_msgs::Header& header) {
  cellsight::ClusterArray out;
  out.header = header;
  out.support_found = r.plane_found;
  if (r.plane_found) out.support_plane = {r.support.n.x(), r.support.n.y(), r.support.n.z(), r.support.d};
  out.support_points = pointsMsg(r.support_points, header);
  out.fragments = pointsMsg(r.fragments, header);
  out.input_points = static_cast<uint32_t>(r.input_points);
  out.points_above_support = static_cast<uint32_t>(r.after_plane);
  out.warnings = r.warnings;
  for (const auto& c : r.clusters) {
    cellsight::Cluster cm;
    cm.cloud = toCloudMsg(c.cloud, header.stamp);
    cm.cloud.header.frame_id = header.frame_id;
    cm.centroid = toPointMsg(c.centroid);
    cm.box_min = toPointMsg(c.box.min());
    cm.box_max = toPointMsg(c.box.max());
    out.clusters.push_back(std::move(cm));
  }
  return out;
}

cellsight::ScanPass toScanPass(const cellsight::ClusterArray& msg, const Eigen::Vector3f& viewpoint,
                               std::vector<std::string>* warnings) {
  cellsight::ScanPass pass;
  for (const auto& c : msg.clusters) {
    try {
      pass.clusters.push_back(fromCloudMsg(c.cloud));
    } catch (const std::exception& e) {
      warnings->push_back(std::string("a cluster cloud was unreadable: ") + e.what());
      pass.clusters.emplace_back();
    }
  }
  cellsight::ScanEvidence& evidence = pass.evidence;
  evidence.viewpoint = viewpoint;
  const Eigen::Vector4f support(static_cast<float>(msg.support_plane[0]), static_cast<float>(msg.support_plane[1]),
                                static_cast<float>(msg.support_plane[2]), static_cast<float>(msg.support_plane[3]));
  const bool use_support = msg.support_found && support.allFinite() && std::abs(support.head<3>().norm() - 1.f) < 1e-3f;
  if (use_support) evidence.support_plane = support;
  if (use_support && msg.support_points.width * msg.support_points.height > 0) {
    try {
      evidence.support_points = fromCloudMsg(msg.support_points).points;
    } catch (const std::exception& e) {
      warnings->push_back(std::string("support_points unreadable, no free-space test: ") + e.what());
    }
  }
  if (msg.fragments.width * msg.fragments.height > 0) {
    try {
      evidence.fragments = fromCloudMsg(msg.fragments).points;
    } catch (const std::exception& e) {
      warnings->push_back(std::string("fragments unreadable, the fitness counts the clusters only: ") + e.what());
    }
  }
  return pass;
}

nlohmann::json detectionsToJson(const cellsight::DetectionArray& out) {
  nlohmann::json j;
  j["frame_id"] = out.header.frame_id;
  j["stamp"] = out.header.stamp.toSec();
  j["clusters"] = out.clusters;
  j["locate_seconds"] = out.locate_seconds;
  j["warnings"] = out.warnings;
  j["cycle_id"] = out.cycle_id;
  j["passes"] = nlohmann::json::array();
  for (const uint8_t r : out.passes) j["passes"].push_back(cellsight::passRoleName(static_cast<cellsight::PassRole>(r)));
  j["final"] = static_cast<bool>(out.final);
  j["detections"] = nlohmann::json::array();
  for (const auto& d : out.detections) {
    const auto& q = d.pose.orientation;
    j["detections"].push_back({{"model", d.model},
                               {"name", d.name},
                               {"xyz", {d.pose.position.x, d.pose.position.y, d.pose.position.z}},
                               {"quat", {q.x, q.y, q.z, q.w}},
                               {"fitness", d.fitness},
                               {"coverage", d.coverage},
                               {"rmse", d.rmse},
                               {"matcher", d.matcher},
                               {"cluster", d.cluster},
                               {"ambiguous_poses", nlohmann::json::array()},
                               {"alternative_score_share", d.alternative_score_share}});
    for (const auto& a : d.ambiguous_poses)
      j["detections"].back()["ambiguous_poses"].push_back(
          {{"xyz", {a.position.x, a.position.y, a.position.z}},
           {"quat", {a.orientation.x, a.orientation.y, a.orientation.z, a.orientation.w}}});
  }
  return j;
}

size_t passOfFrame(const std::vector<ros::Time>& goals_sent, const ros::Time& stamp) {
  const auto after = std::upper_bound(goals_sent.begin(), goals_sent.end(), stamp);
  return after == goals_sent.begin() ? 0 : static_cast<size_t>(after - goals_sent.begin() - 1);
}

std::string passOutputFile(const std::string& file, size_t k) {
  if (file.empty() || k == 0) return file;
  const size_t dot = file.find_last_of('.'), slash = file.find_last_of('/');
  const size_t at = dot == std::string::npos || (slash != std::string::npos && dot < slash) ? file.size() : dot;
  return file.substr(0, at) + "_pass" + std::to_string(k) + file.substr(at);
}

std::string outputNameProblem(const std::string& name, const std::vector<std::string>& extensions) {
  if (name.empty()) return "";
  const bool plain = name.size() <= 128 && name[0] != '.' && std::all_of(name.begin(), name.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '.' || c == '_' || c == '-';
  });
  if (!plain) return "'" + name.substr(0, 128) + "' is not a plain file name (letters, digits, '.', '_', '-'; no '/', not hidden)";
  for (const auto& e : extensions)
    if (name.size() > e.size() && name.compare(name.size() - e.size(), e.size(), e) == 0) return "";
  std::string list;
  for (const auto& e : extensions) list += (list.empty() ? "" : ", ") + e;
  return "'" + name + "' must end in " + list;
}

}  // namespace cellsight_ros
