#include "cellsight_ros/conversions.hpp"

#include <sensor_msgs/image_encodings.h>

#include <cmath>
#include <stdexcept>

namespace cellsight_ros {

geometry_msgs::Pose toPoseMsg(const Eigen::Isometry3d& T) {
  geometry_msgs::Pose p;
  p.position.x = T.translation().x();
  p.position.y = T.translation().y();
  p.position.z = T.translation().z();
  const Eigen::Quaterniond q(T.linear());
  p.orientation.x = q.x();
  p.orientation.y = q.y();
  p.orientation.z = q.z();
  p.orientation.w = q.w();
  return p;
}

Eigen::Isometry3d fromPoseMsg(const geometry_msgs::Pose& p) {
  Eigen::Quaterniond q(p.orientation.w, p.orientation.x, p.orientation.y, p.orientation.z);
  if (!std::isfinite(q.norm()) || q.norm() < 1e-6) {
    throw std::invalid_argument("pose orientation is not a valid quaternion");
  }
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = q.normalized().toRotationMatrix();
  T.translation() << p.position.x, p.position.y, p.position.z;
  if (!T.translation().allFinite()) throw std::invalid_argument("pose position is not finite");
  return T;
}

geometry_msgs::Transform toTransformMsg(const Eigen::Isometry3d& T) {
  const geometry_msgs::Pose p = toPoseMsg(T);
  geometry_msgs::Transform t;
  t.translation.x = p.position.x;
  t.translation.y = p.position.y;
  t.translation.z = p.position.z;
  t.rotation = p.orientation;
  return t;
}

Eigen::Isometry3d fromTransformMsg(const geometry_msgs::Transform& t) {
  geometry_msgs::Pose p;
  p.position.x = t.translation.x;
  p.position.y = t.translation.y;
  p.position.z = t.translation.z;
  p.orientation = t.rotation;
  return fromPoseMsg(p);
}

geometry_msgs::TransformStamped toTransformStamped(const cellsight::TransformCalibration& cal,
                                                   const ros::Time& stamp) {
  geometry_msgs::TransformStamped ts;
  ts.header.stamp = stamp;
  ts.header.frame_id = cal.parent_frame;
  ts.child_frame_id = cal.child_frame;
  ts.transform = toTransformMsg(cal.T_parent_child);
  return ts;
}

cellsight::LaserPlaneStamped toPlaneMsg(const cellsight::Plane& plane, const std::string& frame,
                                        const ros::Time& stamp) {
  cellsight::LaserPlaneStamped m;
  m.header.frame_id = frame;
  m.header.stamp = stamp;
  m.normal.x = plane.n.x();
  m.normal.y = plane.n.y();
  m.normal.z = plane.n.z();
  m.d = plane.d;
  return m;
}

cellsight::Plane fromPlaneMsg(const cellsight::LaserPlaneStamped& m) {
  cellsight::Plane p;
  p.n << m.normal.x, m.normal.y, m.normal.z;
  const double norm = p.n.norm();
  if (!std::isfinite(norm) || norm < 1e-9 || !std::isfinite(m.d)) {
    throw std::invalid_argument("laser plane has a zero or non-finite normal or offset");
  }
  p.n /= norm;
  p.d = m.d / norm;
  return p;
}

sensor_msgs::CameraInfo toCameraInfo(const cellsight::CameraIntrinsics& c,
                                     const std::string& frame, const ros::Time& stamp) {
  sensor_msgs::CameraInfo ci;
  ci.header.frame_id = frame;
  ci.header.stamp = stamp;
  ci.width = static_cast<uint32_t>(c.width);
  ci.height = static_cast<uint32_t>(c.height);
  ci.distortion_model = "plumb_bob";
  ci.D.assign(c.dist.begin(), c.dist.end());
  ci.K = {c.fx, 0, c.cx, 0, c.fy, c.cy, 0, 0, 1};
  ci.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  ci.P = {c.fx, 0, c.cx, 0, 0, c.fy, c.cy, 0, 0, 0, 1, 0};
  return ci;
}

cellsight::CameraIntrinsics fromCameraInfo(const sensor_msgs::CameraInfo& ci) {
  if (ci.distortion_model != "plumb_bob" && !ci.distortion_model.empty() &&
      ci.distortion_model != "rational_polynomial") {
    throw std::invalid_argument("camera_info distortion model '" + ci.distortion_model +
                                "' is not supported (use plumb_bob)");
  }
  cellsight::CameraIntrinsics c;
  c.width = static_cast<int>(ci.width);
  c.height = static_cast<int>(ci.height);
  c.fx = ci.K[0];
  c.fy = ci.K[4];
  c.cx = ci.K[2];
  c.cy = ci.K[5];
  for (size_t i = 0; i < 5 && i < ci.D.size(); ++i) c.dist[i] = ci.D[i];
  try {
    c.validate("camera_info (" + ci.header.frame_id + ")");
  } catch (const std::exception& e) {
    throw std::invalid_argument(e.what());
  }
  return c;
}

sensor_msgs::Image toImageMsg(const cv::Mat& image, const std::string& frame,
                              const ros::Time& stamp) {
  sensor_msgs::Image m;
  m.header.frame_id = frame;
  m.header.stamp = stamp;
  m.height = static_cast<uint32_t>(image.rows);
  m.width = static_cast<uint32_t>(image.cols);
  if (image.type() == CV_8UC1) {
    m.encoding = sensor_msgs::image_encodings::MONO8;
  } else if (image.type() == CV_8UC3) {
    m.encoding = sensor_msgs::image_encodings::RGB8;
  } else {
    throw std::invalid_argument("toImageMsg: only CV_8UC1 and CV_8UC3 images are supported");
  }
  m.is_bigendian = 0;
  m.step = static_cast<uint32_t>(image.cols * image.elemSize());
  m.data.resize(static_cast<size_t>(m.step) * m.height);
  for (int r = 0; r < image.rows; ++r) {
    std::memcpy(&m.data[static_cast<size_t>(r) * m.step], image.ptr(r), m.step);
  }
  return m;
}

int64_t toNanoseconds(const ros::Time& t) { return static_cast<int64_t>(t.toNSec()); }
ros::Time fromNanoseconds(int64_t ns) {
  ros::Time t;
  t.fromNSec(static_cast<uint64_t>(ns));
  return t;
}

}  // namespace cellsight_ros
