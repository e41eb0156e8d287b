// The calibration services take their data in the request and answer the result: real
// chessboard images give intrinsics (in the response and in ~calibration_dir); bad requests are
// refused with a status and a message naming the cause, and the previous file stays untouched.
#include <gtest/gtest.h>

#include <tuple>
#include <ros/package.h>
#include <ros/ros.h>

#include <algorithm>
#include <cmath>
#include <filesystem>
#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <sstream>

#include "cellsight/CalibrateExtrinsics.h"
#include "cellsight/CalibrateIntrinsics.h"
#include "cellsight/CalibrateLaser.h"
#include "cellsight/common/camera_model.hpp"
#include "cellsight_ros/conversions.hpp"

namespace {
std::string slurp(const std::string& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}

std::string calibrationDir() {
  std::string dir;
  ros::NodeHandle("~").getParam("calibration_dir", dir);
  return dir;
}
}  // namespace

TEST(CalibrationServices, IntrinsicsFromImagesInTheRequest) {
  ros::NodeHandle nh;
  auto client = nh.serviceClient<cellsight::CalibrateIntrinsics>("scanner_calibration/intrinsics");
  ASSERT_TRUE(client.waitForExistence(ros::Duration(30)));
  const std::string data = ros::package::getPath("cellsight") + "/../shared/data/calibration/opencv_chessboard_9x6";
  if (!std::filesystem::is_directory(data)) GTEST_SKIP() << data << " is missing";
  std::vector<std::string> files;
  for (const auto& e : std::filesystem::directory_iterator(data)) {
    const std::string ext = e.path().extension().string();
    if (ext == ".png" || ext == ".jpg") files.push_back(e.path().string());
  }
  std::sort(files.begin(), files.end());
  cellsight::CalibrateIntrinsics srv;
  for (const auto& f : files)
    srv.request.images.push_back(cellsight_ros::toImageMsg(cv::imread(f, cv::IMREAD_GRAYSCALE), "test_camera", ros::Time::now()));
  srv.request.board_cols = 9;
  srv.request.board_rows = 6;
  srv.request.square_size = 0.025;
  srv.request.model = "full";
  srv.request.camera_name = "test_camera";
  ASSERT_TRUE(client.call(srv));
  ASSERT_EQ(srv.response.status, cellsight::CalibrateIntrinsics::Response::OK) << srv.response.message;
  EXPECT_LT(srv.response.rms_px, 0.393 * 1.1);  // OpenCV's own result 0.393 px: unchanged or better
  EXPECT_EQ(srv.response.per_view_rms_px.size(), srv.response.views_used);
  EXPECT_GT(srv.response.camera_info.K[0], 100.0);
  EXPECT_EQ(srv.response.file, calibrationDir() + "/test_camera.yaml");
  const cellsight::CameraIntrinsics written = cellsight::loadCameraInfoYaml(srv.response.file);
  EXPECT_NEAR(written.fx, srv.response.camera_info.K[0], 1e-6);
}

TEST(CalibrationServices, BadRequestsAreRefusedAndThePreviousFileStays) {
  ros::NodeHandle nh;
  const std::string dir = calibrationDir();
  std::filesystem::create_directories(dir);
  const std::string cam_file = dir + "/scanner_camera.yaml", laser_file = dir + "/laser.yaml",
                    pose_file = dir + "/scanner_camera_optical.yaml";
  for (const auto& f : {cam_file, laser_file, pose_file}) std::ofstream(f) << "previous: calibration\n";

  auto intrinsics = nh.serviceClient<cellsight::CalibrateIntrinsics>("scanner_calibration/intrinsics");
  ASSERT_TRUE(intrinsics.waitForExistence(ros::Duration(30)));
  cellsight::CalibrateIntrinsics none;
  none.request.board_cols = 9;
  none.request.board_rows = 6;
  none.request.square_size = 0.025;
  ASSERT_TRUE(intrinsics.call(none));
  EXPECT_EQ(none.response.status, cellsight::CalibrateIntrinsics::Response::FAILED);
  EXPECT_NE(none.response.message.find("no images"), std::string::npos) << none.response.message;
  cellsight::CalibrateIntrinsics odd = none;
  sensor_msgs::Image img;
  img.width = img.height = 4;
  img.encoding = "32FC1";
  img.step = 16;
  img.data.assign(64, 0);
  odd.request.images = {img, img, img};
  ASSERT_TRUE(intrinsics.call(odd));
  EXPECT_EQ(odd.response.status, cellsight::CalibrateIntrinsics::Response::FAILED);
  EXPECT_NE(odd.response.message.find("32FC1"), std::string::npos) << odd.response.message;

  auto extrinsics = nh.serviceClient<cellsight::CalibrateExtrinsics>("scanner_calibration/extrinsics");
  cellsight::CalibrateExtrinsics ext;
  ext.request.camera_info = cellsight_ros::toCameraInfo(
      cellsight::CameraIntrinsics{"scanner_camera", 640, 480, 800, 800, 319.5, 239.5, {0, 0, 0, 0, 0}},
      "scanner_camera_optical", ros::Time::now());
  ext.request.image = cellsight_ros::toImageMsg(cv::Mat(480, 640, CV_8UC1, cv::Scalar(128)), "scanner_camera_optical",
                                                ros::Time::now());
  ext.request.board_cols = 9;
  ext.request.board_rows = 6;
  ext.request.square_size = 0.025;
  ext.request.on_x.x = 0.1;
  ext.request.in_xy.y = NAN;  // a NaN taught point
  ASSERT_TRUE(extrinsics.call(ext));
  EXPECT_EQ(ext.response.status, cellsight::CalibrateExtrinsics::Response::FAILED);
  EXPECT_NE(ext.response.message.find("not finite"), std::string::npos) << ext.response.message;

  auto laser = nh.serviceClient<cellsight::CalibrateLaser>("scanner_calibration/laser");
  cellsight::CalibrateLaser l;
  l.request.images.resize(2);
  l.request.flange_poses.resize(1);
  l.request.plane_z = {0.0, 0.0};
  ASSERT_TRUE(laser.call(l));
  EXPECT_EQ(l.response.status, cellsight::CalibrateLaser::Response::FAILED);
  EXPECT_NE(l.response.message.find("one entry per observation"), std::string::npos) << l.response.message;

  // names become file names and YAML: only ROS names; sizes within a board's
  cellsight::CalibrateIntrinsics named = odd;
  named.request.camera_name = "a: [b";
  ASSERT_TRUE(intrinsics.call(named));
  EXPECT_EQ(named.response.status, cellsight::CalibrateIntrinsics::Response::FAILED);
  EXPECT_NE(named.response.message.find("is not a ROS name"), std::string::npos) << named.response.message;
  named.request.camera_name = ".._escape";
  ASSERT_TRUE(intrinsics.call(named));
  EXPECT_NE(named.response.message.find("is not a ROS name"), std::string::npos) << named.response.message;
  named.request.camera_name = "test_camera";
  named.request.square_size = 1e-300;
  ASSERT_TRUE(intrinsics.call(named));
  EXPECT_NE(named.response.message.find("square size"), std::string::npos) << named.response.message;
  ext.request.in_xy.y = 0.1;
  for (const auto& [parent, child, why] : {std::tuple<std::string, std::string, std::string>{"base_link", "/abs_frame", "is not a ROS name"},
                                           {"base_link", "base_link", "are both 'base_link'"}}) {
    ext.request.parent_frame = parent;
    ext.request.child_frame = child;
    ASSERT_TRUE(extrinsics.call(ext));
    EXPECT_EQ(ext.response.status, cellsight::CalibrateExtrinsics::Response::FAILED);
    EXPECT_NE(ext.response.message.find(why), std::string::npos) << ext.response.message;
  }
  l.request.laser_frame = "flange";
  ASSERT_TRUE(laser.call(l));
  EXPECT_NE(l.response.message.find("are both 'flange'"), std::string::npos) << l.response.message;

  for (const auto& f : {cam_file, laser_file, pose_file}) EXPECT_EQ(slurp(f), "previous: calibration\n") << f;
  for (const auto& f : std::filesystem::directory_iterator(dir))  // nothing else (the other test writes test_camera.yaml)
    EXPECT_TRUE(f.path() == cam_file || f.path() == laser_file || f.path() == pose_file ||
                f.path().filename() == "test_camera.yaml")
        << f.path();
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_calibration_services");
  return RUN_ALL_TESTS();
}
