// Every translation between core types and ROS messages lives here (round-trip tested).
#pragma once
#include <geometry_msgs/Point.h>
#include <geometry_msgs/Pose.h>
#include <geometry_msgs/Transform.h>
#include <geometry_msgs/TransformStamped.h>
#include <ros/time.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>

#include <Eigen/Geometry>
#include <cstdint>
#include <opencv2/core.hpp>

#include "cellsight/common/calibration.hpp"
#include "cellsight/common/camera_model.hpp"
#include "cellsight/common/mesh.hpp"
#include "cellsight/common/plane.hpp"
#include "cellsight/common/scan_cloud.hpp"
#include "cellsight/Detection.h"
#include "cellsight/GraspPlan.h"
#include "cellsight/LaserPlaneStamped.h"
#include "cellsight/LaserSweep.h"
#include "cellsight/localization/light_sweep.hpp"
#include "cellsight/planning/grasp_planner.hpp"

namespace cellsight {
struct PartDetection;
}  // namespace cellsight

namespace cellsight_ros {

geometry_msgs::Pose toPoseMsg(const Eigen::Isometry3d& T);
geometry_msgs::Point toPointMsg(const Eigen::Vector3f& p);
/// A mesh as the points of an rviz TRIANGLE_LIST marker (three per face, mesh frame); rviz draws
/// these itself, where a MESH_RESOURCE goes through its assimp loader.
std::vector<geometry_msgs::Point> meshTriangles(const cellsight::TriangleMesh& mesh);
Eigen::Isometry3d fromPoseMsg(const geometry_msgs::Pose& msg);
geometry_msgs::Transform toTransformMsg(const Eigen::Isometry3d& T);
Eigen::Isometry3d fromTransformMsg(const geometry_msgs::Transform& msg);
geometry_msgs::TransformStamped toTransformStamped(const cellsight::TransformCalibration& cal,
                                                   const ros::Time& stamp);

cellsight::LaserPlaneStamped toPlaneMsg(const cellsight::Plane& plane, const std::string& frame,
                                        const ros::Time& stamp);
cellsight::Plane fromPlaneMsg(const cellsight::LaserPlaneStamped& msg);
/// One scan's light sheets (frames in time order) as a message, and back. fromLaserSweepMsg
/// throws std::invalid_argument naming the problem: arrays of different lengths, a non-finite
/// value, a normal that is not unit length.
cellsight::LaserSweep toLaserSweepMsg(const cellsight::LightSweep& sweep, const std::string& frame, const ros::Time& stamp);
cellsight::LightSweep fromLaserSweepMsg(const cellsight::LaserSweep& msg);

sensor_msgs::CameraInfo toCameraInfo(const cellsight::CameraIntrinsics& cam,
                                     const std::string& frame, const ros::Time& stamp);
/// Throws std::invalid_argument naming the problem for a CameraInfo that is not usable
/// (zero focal length, unsupported distortion model, non-finite values).
cellsight::CameraIntrinsics fromCameraInfo(const sensor_msgs::CameraInfo& msg);

/// CV_8UC1 → mono8, CV_8UC3 (RGB order) → rgb8.
sensor_msgs::Image toImageMsg(const cv::Mat& image, const std::string& frame, const ros::Time& stamp);

/// A received image as an OpenCV header over the message's bytes (no copy; valid while `msg`
/// lives): mono8 → CV_8UC1, rgb8 / bgr8 → CV_8UC3 in the message's channel order. Checks, in
/// 64 bits, the size against kMaxImageSide / kMaxImagePixels, step ≥ width × channels and
/// step × height = data size; throws std::invalid_argument naming the encoding or the field.
cv::Mat fromImageMsg(const sensor_msgs::Image& msg);

/// x y z intensity [normal_x normal_y normal_z] (float32), unorganised, dense.
sensor_msgs::PointCloud2 toCloudMsg(const cellsight::ScanCloud& cloud, const ros::Time& stamp);
/// Reads x y z (required) and intensity / normals (optional); non-finite points are dropped
/// and counted in `dropped`. Throws std::invalid_argument naming a missing field or bad layout.
cellsight::ScanCloud fromCloudMsg(const sensor_msgs::PointCloud2& msg, size_t* dropped = nullptr);

int64_t toNanoseconds(const ros::Time& t);
ros::Time fromNanoseconds(int64_t ns);

/// A located part as a Detection named `name` (its tf child frame, object/<n>): the pose and the
/// turns the scan cannot tell from it (ambiguous_poses) in the frame it was located in, and the
/// matcher's figures.
cellsight::Detection toDetectionMsg(const cellsight::PartDetection& d, const std::string& name);

/// A planner result as a GraspPlan (trajectory with the arm's joint names, times from `stamp`).
cellsight::GraspPlan toGraspPlanMsg(const cellsight::PartPlan& plan, const std::array<std::string, 6>& joint_names,
                                    const std::string& frame, const ros::Time& stamp);
/// GraspPlan.status of a planner status.
uint8_t toPlanStatus(cellsight::PlanStatus s);
/// A JointTrajectory as positions and times in the arm's joint order. Throws std::invalid_argument
/// naming the problem: no points, joint names that are not the arm's six, a point without six
/// finite positions, times not strictly increasing.
cellsight::TimedTrajectory fromTrajectoryMsg(const trajectory_msgs::JointTrajectory& msg,
                                             const std::array<std::string, 6>& joint_names);

}  // namespace cellsight_ros
