// The calibration services: a real chessboard set gives intrinsics; a bad request is refused
// with a message and the previous file is left untouched.
#include <gtest/gtest.h>
#include <ros/package.h>
#include <ros/ros.h>
#include <sys/stat.h>

#include <fstream>
#include <sstream>

#include "cellsight/CalibrateIntrinsics.h"
#include "cellsight/CalibrateLaser.h"

namespace {
std::string slurp(const std::string& p) {
  std::ifstream in(p);
  std::stringstream s;
  s << in.rdbuf();
  return s.str();
}
}  // namespace

TEST(CalibrationServices, IntrinsicsFromRealImagesAndRefusalKeepsTheOldFile) {
  ros::NodeHandle nh;
  auto client = nh.serviceClient<cellsight::CalibrateIntrinsics>("scanner_calibration/intrinsics");
  ASSERT_TRUE(client.waitForExistence(ros::Duration(30)));
  const std::string data = ros::package::getPath("cellsight") + "/../shared/data/calibration/opencv_chessboard_9x6";
  const std::string out = "/tmp/cellsight_test_intrinsics_" + std::to_string(::getpid()) + ".yaml";
  struct stat st {};
  if (::stat(data.c_str(), &st) == 0) {
    cellsight::CalibrateIntrinsics srv;
    srv.request.images = {data};
    srv.request.board_cols = 9;
    srv.request.board_rows = 6;
    srv.request.square_size = 0.025;
    srv.request.model = "full";
    srv.request.output_file = out;
    ASSERT_TRUE(client.call(srv));
    EXPECT_EQ(srv.response.status, 0) << srv.response.message;
    EXPECT_NEAR(srv.response.rms_px, 0.393, 0.0393);
  } else {
    std::ofstream(out) << "image_width: 1\n";  // stands for a previous calibration
  }
  const std::string before = slurp(out);
  cellsight::CalibrateIntrinsics bad;
  bad.request.images = {"/nonexistent/folder"};
  bad.request.board_cols = 9;
  bad.request.board_rows = 6;
  bad.request.square_size = 0.025;
  bad.request.output_file = out;
  ASSERT_TRUE(client.call(bad));
  EXPECT_EQ(bad.response.status, cellsight::CalibrateIntrinsics::Response::FAILED);
  EXPECT_NE(bad.response.message.find("previous file kept"), std::string::npos);
  EXPECT_EQ(slurp(out), before);

  auto laser = nh.serviceClient<cellsight::CalibrateLaser>("scanner_calibration/laser");
  cellsight::CalibrateLaser l;
  l.request.observations_file = "/nonexistent/obs.yaml";
  l.request.camera_file = out;
  l.request.output_file = out;
  ASSERT_TRUE(laser.call(l));
  EXPECT_EQ(l.response.status, cellsight::CalibrateLaser::Response::FAILED);
  EXPECT_EQ(slurp(out), before);
  std::remove(out.c_str());
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_calibration_services");
  return RUN_ALL_TESTS();
}
