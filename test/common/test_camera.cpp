#include <gtest/gtest.h>

#include <random>

#include "cellsight/common/camera_model.hpp"
#include "cellsight/common/errors.hpp"
#include "test_helpers.hpp"

using cellsight::CameraIntrinsics;

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
