// Pinhole camera with OpenCV/ROS "plumb_bob" distortion (k1, k2, p1, p2, k3), and the ROS
// camera_info YAML format (the same files camera_calibration and camera_info_manager use).
#pragma once
#include <cstdint>
#include <Eigen/Core>
#include <array>
#include <string>

namespace cellsight {

/// The largest image the stack accepts (camera_info, calibration files, images read from disk).
constexpr int kMaxImageSide = 32768;
constexpr int64_t kMaxImagePixels = 64ll * 1024 * 1024;

struct CameraIntrinsics {
  std::string camera_name = "camera";
  int width = 0, height = 0;
  double fx = 0, fy = 0, cx = 0, cy = 0;
  std::array<double, 5> dist{0, 0, 0, 0, 0};  ///< plumb_bob: k1, k2, p1, p2, k3

  /// Normalised undistorted coordinates (x/z, y/z) → distorted pixel.
  Eigen::Vector2d distortNormalized(const Eigen::Vector2d& xn) const;
  /// Camera-frame point (z > 0, REP 103 optical frame) → pixel, with distortion.
  Eigen::Vector2d project(const Eigen::Vector3d& p_camera) const;
  /// Pixel → normalised undistorted coordinates (iterative; converges to < 1e-12 for
  /// realistic lenses).
  Eigen::Vector2d undistortPixel(const Eigen::Vector2d& pixel) const;
  /// Pixel → unit ray in the camera frame.
  Eigen::Vector3d pixelRay(const Eigen::Vector2d& pixel) const;

  /// Throws ConfigError (prefixed with `where`) if sizes or focal lengths are not sane.
  void validate(const std::string& where) const;
};

/// Reads a ROS camera_info YAML file. Throws ConfigError naming the file and key.
CameraIntrinsics loadCameraInfoYaml(const std::string& path);
/// Serialises to the ROS camera_info YAML format.
std::string cameraInfoYaml(const CameraIntrinsics& cam);
/// Writes the camera_info YAML atomically, after checking it as loadCameraInfoYaml would.
void saveCameraInfoYaml(const std::string& path, const CameraIntrinsics& cam);

}  // namespace cellsight
