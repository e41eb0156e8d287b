// laser_plane_tracker: the light sheet in the scanner camera frame at each image's stamp.
// For every scanner_camera/camera_info (one per frame) it looks up T_camera_laser at that stamp
// through tf2 (flange pose from the robot × calibrated flange→laser) and publishes
// scan/laser_plane. A frame whose transform is missing is dropped with a throttled log naming
// the frames and the stamp; no identity, no "latest" fallback.
#include <message_filters/subscriber.h>
#include <ros/ros.h>

#include <atomic>
#include <sensor_msgs/CameraInfo.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/message_filter.h>
#include <tf2_ros/transform_listener.h>

#include "cellsight_ros/conversions.hpp"
#include "cellsight_ros/node.hpp"
#include "cellsight_ros/diagnostics.hpp"
#include "cellsight_ros/params.hpp"

namespace {

class LaserPlaneTracker {
 public:
  LaserPlaneTracker(ros::NodeHandle& nh, ros::NodeHandle& pnh)
      : diag_(nh, pnh, "laser_plane_tracker", "frames"), listener_(buffer_), info_sub_(nh, "scanner_camera/camera_info", 60),
        filter_(info_sub_, buffer_, "laser", 60, nh) {
    cellsight_ros::param(pnh, "laser_frame", laser_frame_);
    double tolerance = 0.0;
    cellsight_ros::param(pnh, "tf_tolerance", tolerance);
    filter_.setTargetFrame(laser_frame_);
    filter_.setTolerance(ros::Duration(tolerance));
    filter_.registerCallback(&LaserPlaneTracker::onInfo, this);
    filter_.registerFailureCallback(
        [this](const sensor_msgs::CameraInfoConstPtr& msg, tf2_ros::filter_failure_reasons::FilterFailureReason reason) {
          ++dropped_;
          diag_.dropped(reason == tf2_ros::filter_failure_reasons::OutTheBack ? "older than the tf buffer"
                                                                               : "no laser transform at the frame's stamp");
          ROS_WARN_THROTTLE(2.0,
                            "laser_plane_tracker: frame at %.6f dropped: no transform %s -> %s at its "
                            "stamp (%s; %lu dropped so far). Is the robot publishing %s in tf and "
                            "calibration_publisher running?",
                            msg->header.stamp.toSec(), msg->header.frame_id.c_str(), laser_frame_.c_str(),
                            reason == tf2_ros::filter_failure_reasons::OutTheBack ? "older than the tf buffer"
                                                                                 : "transform unavailable",
                            dropped_.load(), "base_link -> flange");
        });
    plane_pub_ = nh.advertise<cellsight::LaserPlaneStamped>("scan/laser_plane", 60);
  }

 private:
  void onInfo(const sensor_msgs::CameraInfoConstPtr& msg) {
    try {
      const auto T = buffer_.lookupTransform(msg->header.frame_id, laser_frame_, msg->header.stamp);
      const cellsight::Plane plane = cellsight::laserPlane(cellsight_ros::fromTransformMsg(T.transform));
      plane_pub_.publish(cellsight_ros::toPlaneMsg(plane, msg->header.frame_id, msg->header.stamp));
      diag_.processed();
    } catch (const std::exception& e) {
      ROS_WARN_THROTTLE(2.0, "laser_plane_tracker: frame at %.6f dropped: %s", msg->header.stamp.toSec(), e.what());
      diag_.dropped("bad laser transform");
    }
  }

  cellsight_ros::NodeDiagnostics diag_;
  std::string laser_frame_ = "laser";
  tf2_ros::Buffer buffer_;
  tf2_ros::TransformListener listener_;
  message_filters::Subscriber<sensor_msgs::CameraInfo> info_sub_;
  tf2_ros::MessageFilter<sensor_msgs::CameraInfo> filter_;
  ros::Publisher plane_pub_;
  std::atomic<unsigned long> dropped_{0};  // failure callbacks may run on several threads (nodelet)
};

}  // namespace

CELLSIGHT_NODE(LaserPlaneTracker, "laser_plane_tracker", 1)
