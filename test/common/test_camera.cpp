#include <gtest/gtest.h>

#include <fstream>
#include <opencv2/imgcodecs.hpp>
#include <random>

#include "cellsight/common/camera_model.hpp"
#include "cellsight/common/errors.hpp"
#include "cellsight/common/image_io.hpp"
#include "test_helpers.hpp"

using cellsight::CameraIntrinsics;
using cellsight::ConfigError;
using cellsight::imageHeaderSize;
using cellsight::readImage;

TEST(Camera, ProjectUnprojectRoundTrip) {
  CameraIntrinsics c{"c", 1920, 1080, 2400, 2390, 962.5, 537.0, {-0.08, 0.05, 0.0003, -0.0002, 0.01}};
  std::mt19937 rng(42);
  std::uniform_real_distribution<double> u(0, 1920), v(0, 1080);
  for (int i = 0; i < 1000; ++i) {
    const Eigen::Vector2d px(u(rng), v(rng));
    const Eigen::Vector3d ray = c.pixelRay(px);
    EXPECT_NEAR((c.project(ray * 0.7) - px).norm(), 0.0, 1e-9);
  }
}

TEST(Camera, CameraInfoYamlRoundTripAndErrors) {
  const std::string dir = cellsight_test::tempDir();
  CameraIntrinsics c{"scanner_camera", 1920, 1080, 2400, 2390, 962.5, 537.0, {-0.08, 0.05, 0.0003, -0.0002, 0.01}};
  cellsight::saveCameraInfoYaml(dir + "/c.yaml", c);
  const CameraIntrinsics b = cellsight::loadCameraInfoYaml(dir + "/c.yaml");
  EXPECT_EQ(b.camera_name, "scanner_camera");
  EXPECT_EQ(b.width, 1920);
  EXPECT_DOUBLE_EQ(b.fy, 2390);
  EXPECT_DOUBLE_EQ(b.dist[4], 0.01);
  // a name YAML would read as structure is written quoted and read back as it was
  CameraIntrinsics odd = c;
  odd.camera_name = "a: [b";
  cellsight::saveCameraInfoYaml(dir + "/odd.yaml", odd);
  EXPECT_EQ(cellsight::loadCameraInfoYaml(dir + "/odd.yaml").camera_name, "a: [b");
  // intrinsics its loader would refuse are never written; the old file stays
  CameraIntrinsics zero = c;
  zero.fx = 0;
  EXPECT_THROW(cellsight::saveCameraInfoYaml(dir + "/c.yaml", zero), cellsight::ConfigError);
  EXPECT_DOUBLE_EQ(cellsight::loadCameraInfoYaml(dir + "/c.yaml").fx, 2400);
  cellsight_test::writeText(dir + "/bad.yaml",
                            "image_width: 640\nimage_height: 480\ncamera_matrix: {rows: 3, cols: 3, "
                            "data: [0, 0, 320, 0, 500, 240, 0, 0, 1]}\ndistortion_model: plumb_bob\n"
                            "distortion_coefficients: {rows: 1, cols: 5, data: [0, 0, 0, 0, 0]}\n");
  try {
    cellsight::loadCameraInfoYaml(dir + "/bad.yaml");
    FAIL();
  } catch (const cellsight::ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("focal"), std::string::npos) << e.what();
  }
}

// Issue 19, class 1: an image file's claimed size is checked before it is decoded.
TEST(ImageIo, HeadersClaimingHugeImagesAreRefused) {
  const std::string dir = cellsight_test::tempDir();
  const std::string small = dir + "/small.png";
  cv::imwrite(small, cv::Mat(6, 8, CV_8UC1, cv::Scalar(7)));
  int w = 0, h = 0;
  ASSERT_TRUE(imageHeaderSize(small, &w, &h));
  EXPECT_EQ(w, 8);
  EXPECT_EQ(h, 6);
  EXPECT_EQ(readImage(small, cv::IMREAD_GRAYSCALE).at<uint8_t>(2, 3), 7);
  const std::string jpg = dir + "/small.jpg";
  cv::imwrite(jpg, cv::Mat(10, 12, CV_8UC3, cv::Scalar(1, 2, 3)));
  ASSERT_TRUE(imageHeaderSize(jpg, &w, &h));
  EXPECT_EQ(w, 12);
  EXPECT_EQ(h, 10);
  // the PNG's IHDR rewritten to claim 100000 x 100000
  std::string bytes;
  {
    std::ifstream in(small, std::ios::binary);
    bytes.assign((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  }
  for (int k : {16, 20}) {
    const uint32_t v = 100000;
    bytes[k] = static_cast<char>(v >> 24);
    bytes[k + 1] = static_cast<char>(v >> 16);
    bytes[k + 2] = static_cast<char>(v >> 8);
    bytes[k + 3] = static_cast<char>(v);
  }
  const std::string huge = dir + "/huge.png";
  std::ofstream(huge, std::ios::binary) << bytes;
  try {
    readImage(huge, cv::IMREAD_GRAYSCALE);
    FAIL() << "a 100000^2 PNG was decoded";
  } catch (const std::runtime_error& e) {
    EXPECT_NE(std::string(e.what()).find("over the limit"), std::string::npos) << e.what();
  }
  EXPECT_THROW(readImage(dir + "/missing.png", cv::IMREAD_GRAYSCALE), std::runtime_error);
  // a camera model of that size is refused as well
  const CameraIntrinsics big{"c", 60000, 60000, 1000, 1000, 30000, 30000, {0, 0, 0, 0, 0}};
  EXPECT_THROW(big.validate("test"), ConfigError);
}
