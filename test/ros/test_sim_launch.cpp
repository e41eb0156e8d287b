// Runs against sim.launch: camera_info and images arrive, tf has every calibrated frame and the
// flange, a commanded pose yields the in-position handshake and a triggered frame with the line.
#include <gtest/gtest.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <std_msgs/Bool.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <mutex>

#include "cellsight/MoveFlange.h"
#include "cellsight_ros/conversions.hpp"

namespace {
template <typename M>
boost::shared_ptr<const M> waitFor(const std::string& topic, double seconds) {
  return ros::topic::waitForMessage<M>(topic, ros::Duration(seconds));
}
}  // namespace

TEST(SimLaunch, FixtureCameraPublishes) {
  auto info = waitFor<sensor_msgs::CameraInfo>("fixture_camera/camera_info", 60);
  ASSERT_TRUE(info) << "no fixture_camera/camera_info within 60 s";
  EXPECT_EQ(info->header.frame_id, "fixture_camera_optical");
  auto img = waitFor<sensor_msgs::Image>("fixture_camera/image_raw", 10);
  ASSERT_TRUE(img);
  EXPECT_EQ(img->encoding, "mono8");
  EXPECT_EQ(img->width, info->width);
}

TEST(SimLaunch, CalibratedFramesAndFlangeInTf) {
  tf2_ros::Buffer buffer;
  tf2_ros::TransformListener listener(buffer);
  for (const char* frame : {"scanner_camera_optical", "fixture_camera_optical", "flange", "laser"}) {
    EXPECT_TRUE(buffer.canTransform("base_link", frame, ros::Time(0), ros::Duration(30.0)))
        << "no tf base_link -> " << frame;
  }
}

TEST(SimLaunch, MoveTriggersACapturedFrameWithTheLine) {
  ros::NodeHandle nh;
  ros::ServiceClient move = nh.serviceClient<cellsight::MoveFlange>("robot/move_flange");
  ASSERT_TRUE(move.waitForExistence(ros::Duration(30.0)));
  std::mutex mutex;
  std::vector<bool> io;
  ros::Subscriber s = nh.subscribe<std_msgs::Bool>("io/in_position", 10, [&](const std_msgs::BoolConstPtr& b) {
    std::lock_guard<std::mutex> lock(mutex);
    io.push_back(b->data);
  });
  sensor_msgs::ImageConstPtr frame;
  ros::Subscriber imgs = nh.subscribe<sensor_msgs::Image>(
      "scanner_camera/image_raw", 2, [&](const sensor_msgs::ImageConstPtr& m) {
        std::lock_guard<std::mutex> lock(mutex);
        frame = m;
      });
  ros::Duration(0.5).sleep();

  cellsight::MoveFlange srv;
  srv.request.target.header.frame_id = "base_link";
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  T.translation() << 0.52, -0.09, 0.30;  // line across the middle of the workspace
  srv.request.target.pose = cellsight_ros::toPoseMsg(T);
  ASSERT_TRUE(move.call(srv));
  ASSERT_EQ(srv.response.status, 0) << srv.response.message;

  // Busy while moving; NaN targets are refused with a message, the node keeps running.
  cellsight::MoveFlange again = srv;
  ASSERT_TRUE(move.call(again));
  EXPECT_EQ(again.response.status, cellsight::MoveFlange::Response::REJECTED_BUSY);
  cellsight::MoveFlange bad = srv;
  bad.request.target.pose.orientation.w = std::nan("");
  ASSERT_TRUE(move.call(bad));
  EXPECT_EQ(bad.response.status, cellsight::MoveFlange::Response::REJECTED_INVALID);

  const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(20.0);
  auto received = [&] {
    std::lock_guard<std::mutex> lock(mutex);
    return static_cast<bool>(frame);
  };
  while (!received() && ros::WallTime::now() < deadline) ros::WallDuration(0.01).sleep();
  ros::WallDuration(0.1).sleep();
  std::lock_guard<std::mutex> lock(mutex);
  ASSERT_TRUE(frame) << "no scanner frame after the robot reached its pose";
  ASSERT_FALSE(io.empty());
  EXPECT_TRUE(io.back());
  // The robot refuses to move on until the capture is acknowledged (stop-and-go interlock).
  ASSERT_TRUE(move.call(again));
  EXPECT_EQ(again.response.status, cellsight::MoveFlange::Response::REJECTED_BUSY);
  EXPECT_NE(again.response.message.find("capture_done"), std::string::npos);

  // The laser line: most columns in the workspace have a pixel far above the ambient level.
  ASSERT_EQ(frame->encoding, "mono8");
  int lit_columns = 0;
  for (uint32_t u = 0; u < frame->width; ++u) {
    uint8_t peak = 0;
    for (uint32_t v = 0; v < frame->height; ++v) peak = std::max(peak, frame->data[v * frame->step + u]);
    if (peak > 50) ++lit_columns;  // ambient ≈ 6, noise σ = 2
  }
  EXPECT_GT(lit_columns, static_cast<int>(frame->width) / 2) << lit_columns << " lit columns";
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_sim_launch");
  ros::AsyncSpinner spinner(1);
  spinner.start();
  return RUN_ALL_TESTS();
}
