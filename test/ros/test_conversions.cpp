#include <gtest/gtest.h>

#include "cellsight_ros/conversions.hpp"

using namespace cellsight_ros;

TEST(Conversions, PoseAndTransformRoundTrip) {
  const Eigen::Isometry3d T = Eigen::Translation3d(0.1, -0.2, 0.3) *
                              Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, -2, 0.5).normalized());
  EXPECT_TRUE(fromPoseMsg(toPoseMsg(T)).isApprox(T, 1e-12));
  EXPECT_TRUE(fromTransformMsg(toTransformMsg(T)).isApprox(T, 1e-12));
  geometry_msgs::Pose bad;
  EXPECT_THROW(fromPoseMsg(bad), std::invalid_argument);  // zero quaternion
}

TEST(Conversions, PlaneAndCameraInfoRoundTrip) {
  cellsight::Plane p;
  p.n = Eigen::Vector3d(0.2, -0.5, 0.7).normalized();
  p.d = -0.42;
  const auto back = fromPlaneMsg(toPlaneMsg(p, "cam", ros::Time(12, 34)));
  EXPECT_TRUE(back.n.isApprox(p.n, 1e-12));
  EXPECT_DOUBLE_EQ(back.d, p.d);
  cellsight::LaserPlaneStamped zero;
  EXPECT_THROW(fromPlaneMsg(zero), std::invalid_argument);

  cellsight::CameraIntrinsics c{"c", 1920, 1080, 2400, 2390, 962.5, 537, {-0.08, 0.05, 1e-4, -2e-4, 0.01}};
  const auto ci = toCameraInfo(c, "cam", ros::Time(1, 0));
  const auto c2 = fromCameraInfo(ci);
  EXPECT_EQ(c2.width, 1920);
  EXPECT_DOUBLE_EQ(c2.fy, 2390);
  EXPECT_DOUBLE_EQ(c2.dist[4], 0.01);
  auto broken = ci;
  broken.K[0] = 0;
  EXPECT_THROW(fromCameraInfo(broken), std::invalid_argument);
  broken = ci;
  broken.distortion_model = "equidistant";
  EXPECT_THROW(fromCameraInfo(broken), std::invalid_argument);
}

TEST(Conversions, ImageMessage) {
  cv::Mat m(4, 5, CV_8UC3, cv::Scalar(1, 2, 3));
  const auto msg = toImageMsg(m, "cam", ros::Time(3, 0));
  EXPECT_EQ(msg.encoding, "rgb8");
  EXPECT_EQ(msg.step, 15u);
  EXPECT_EQ(msg.data[2], 3);
  EXPECT_EQ(toImageMsg(cv::Mat(2, 2, CV_8UC1, cv::Scalar(9)), "c", ros::Time()).encoding, "mono8");
  EXPECT_THROW(toImageMsg(cv::Mat(2, 2, CV_32F), "c", ros::Time()), std::invalid_argument);
  EXPECT_EQ(fromNanoseconds(toNanoseconds(ros::Time(5, 7))), ros::Time(5, 7));
}
