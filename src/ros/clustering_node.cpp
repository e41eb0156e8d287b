// clustering: scan/cloud → clusters (cellsight/ClusterArray, one message per scan) and
// clusters/markers (boxes for rviz). Settings from ~settings_file (config/clustering.yaml).
#include <ros/ros.h>
#include <visualization_msgs/MarkerArray.h>

#include "cellsight/ClusterArray.h"
#include "cellsight/localization/clustering.hpp"
#include "cellsight_ros/conversions.hpp"
#include "cellsight_ros/node.hpp"
#include "cellsight_ros/diagnostics.hpp"
#include "cellsight_ros/params.hpp"
#include "cellsight_ros/scan_messages.hpp"

namespace {

class Clustering {
 public:
  Clustering(ros::NodeHandle& nh, ros::NodeHandle& pnh) : diag_(nh, pnh, "clustering", "scans") {
    config_ = cellsight::loadClusteringConfig(cellsight_ros::requireParam<std::string>(
        pnh, "settings_file", "clustering settings YAML, e.g. $(find cellsight)/config/clustering.yaml"));
    clusters_pub_ = nh.advertise<cellsight::ClusterArray>("clusters", 1, true);
    markers_pub_ = nh.advertise<visualization_msgs::MarkerArray>("clusters/markers", 1, true);
    cloud_sub_ = nh.subscribe("scan/cloud", 1, &Clustering::onCloud, this);
  }

 private:
  void onCloud(const sensor_msgs::PointCloud2ConstPtr& msg) {
    const ros::WallTime t0 = ros::WallTime::now();
    try {
      size_t dropped = 0;
      const cellsight::ScanCloud cloud = cellsight_ros::fromCloudMsg(*msg, &dropped);
      const cellsight::ClusteringResult r = cellsight::clusterScene(cloud, config_);
      const cellsight::ClusterArray out = cellsight_ros::toClusterArrayMsg(r, msg->header);
      visualization_msgs::MarkerArray markers;
      visualization_msgs::Marker clear;
      clear.action = visualization_msgs::Marker::DELETEALL;
      markers.markers.push_back(clear);
      int id = 0;
      for (const auto& c : r.clusters) {
        visualization_msgs::Marker m;
        m.header = msg->header;
        m.ns = "clusters";
        m.id = id++;
        m.type = visualization_msgs::Marker::CUBE;
        m.pose.position = cellsight_ros::toPointMsg(c.box.center());
        m.pose.orientation.w = 1;
        m.scale.x = std::max(1e-3f, c.box.sizes().x());
        m.scale.y = std::max(1e-3f, c.box.sizes().y());
        m.scale.z = std::max(1e-3f, c.box.sizes().z());
        m.color.g = 0.8f;
        m.color.b = 0.3f;
        m.color.a = 0.35f;
        markers.markers.push_back(m);
      }
      clusters_pub_.publish(out);
      markers_pub_.publish(markers);
      for (const auto& w : r.warnings) ROS_WARN("clustering: %s", w.c_str());
      ROS_INFO("clustering: %zu points -> %zu clusters%s", r.input_points, r.clusters.size(),
               r.plane_found ? " (support plane removed)" : "");
      diag_.processed((ros::WallTime::now() - t0).toSec());
      diag_.set("clusters in the last scan", std::to_string(r.clusters.size()));
    } catch (const std::exception& e) {
      ROS_ERROR("clustering: scan at %.3f skipped: %s", msg->header.stamp.toSec(), e.what());
      diag_.dropped("unusable scan cloud");
    }
  }

  cellsight_ros::NodeDiagnostics diag_;
  cellsight::ClusteringConfig config_;
  ros::Publisher clusters_pub_, markers_pub_;
  ros::Subscriber cloud_sub_;
};

}  // namespace

CELLSIGHT_NODE(Clustering, "clustering", 1)
