// Laser triangulation (thesis §1): each line centre's undistorted camera ray cut with the light
// sheet n·P + d = 0 (camera frame): t = −d / (n·r), P = t·r.
#pragma once
#include <Eigen/Core>
#include <vector>

#include "cellsight/common/camera_model.hpp"
#include "cellsight/scanner/line_extraction.hpp"
#include "cellsight/common/plane.hpp"

namespace cellsight {

struct TriangulationConfig {
  double min_ray_plane_angle = 0.05;  ///< rad; flatter rays are ill-conditioned and dropped
  double min_range = 0.02;            ///< m from the camera centre
  double max_range = 5.0;
};

struct ProfilePoint {
  Eigen::Vector3d p;  ///< camera frame, metres
  float intensity = 0;
  float u = 0, v = 0;
};

/// Undistorted normalised coordinates for every pixel, built once per camera; sub-pixel
/// look-ups interpolate bilinearly (error < 1e-7 of the iterative solution for lenses like the
/// demo's). Use it when triangulating many frames of one camera.
class UndistortionMap {
 public:
  explicit UndistortionMap(const CameraIntrinsics& camera);
  /// Normalised (x/z, y/z) of a sub-pixel position; falls back to the iterative solution
  /// outside the image.
  Eigen::Vector2d operator()(double u, double v) const;
  const CameraIntrinsics& camera() const { return camera_; }

 private:
  CameraIntrinsics camera_;
  std::vector<float> xy_;  // interleaved x, y per pixel, row-major
};

std::vector<ProfilePoint> triangulate(const std::vector<LinePoint>& line, const UndistortionMap& map,
                                      const Plane& plane_camera, const TriangulationConfig& config = {});

/// Triangulates line centres against the sheet (camera frame). Points whose ray is nearly
/// parallel to the sheet, or outside [min_range, max_range], are dropped.
std::vector<ProfilePoint> triangulate(const std::vector<LinePoint>& line,
                                      const CameraIntrinsics& camera, const Plane& plane_camera,
                                      const TriangulationConfig& config = {});

}  // namespace cellsight
