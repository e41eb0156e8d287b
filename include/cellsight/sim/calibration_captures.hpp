// What a user records to calibrate the scanner, simulated on the cell as built: chessboard
// views for the intrinsics, the board lying in the cell with its frame taught by the robot's
// pointer (camera pose), views of the laser line on the bare table from several flange poses
// (light sheet, least squares) and one over a gauge block (the thesis's three-point method).
// The files are written in the formats `cellsight_calibrate` reads; the robot reports the
// poses it was told (its own kinematic error and scatter are in the images, not in the files).
#pragma once
#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "cellsight/sim/scene.hpp"

namespace cellsight {

struct CalibrationCaptureConfig {
  int board_cols = 9, board_rows = 6;  ///< inner corners per row, per column
  double square = 0.025;               ///< metres
  double fixture_square = 0.05;        ///< the fixture camera's board (same corner count), metres
  int hand_eye_views = 20;             ///< fixture camera to robot: views of a board on the tool
  double hand_eye_square = 0.03;       ///< that board's squares (same corner count), metres
  int intrinsic_views = 15;
  int laser_views = 12;
  double tcp_length = 0.15;            ///< pointer tip along the flange z axis, metres
  double pointer_sigma_mm = 0.05;      ///< how well the user puts the pointer tip on a corner (σ per axis)
  double gauge_block_height = 0.02;    ///< metres (a gauge block: exact)
  uint64_t seed = 1;
};

/// A chessboard on a white plate (one square of margin) seen by `camera`: the board frame has
/// its origin at the first inner corner, x along the rows, y along the columns, z = x × y (into
/// the board, away from the printed side); the square between the first four corners is black.
/// Rays that miss the plate fall on the table. Grey levels: white 200, black 25 (× the light);
/// sensor noise from `noise`. 8-bit grey, the camera's resolution.
cv::Mat renderChessboardView(const Scene& scene, const CameraConfig& camera, const Eigen::Isometry3d& T_base_board,
                             const CalibrationCaptureConfig& board, uint64_t seed);

/// Flange poses for an eye-to-hand calibration of a stationary, downward-looking `camera`: a
/// target (its points in its own frame) carried at T_flange_target. The first seven are a
/// reference 0.25 m above the table point under the camera and ±50 mm moves along the base axes
/// from it (orientation unchanged: the thesis's axes method); then poses tilted up to 25° with a
/// yaw within ±45°, every target point in the image (30 px margin), the target facing the camera.
std::vector<Eigen::Isometry3d> handEyeFlangePoses(const Scene& scene, const CameraConfig& camera,
                                                  const Eigen::Isometry3d& T_flange_target,
                                                  const std::vector<Eigen::Vector3d>& target_points, int count,
                                                  uint64_t seed);

struct CalibrationCaptureFiles {
  std::string intrinsics_dir;   ///< view_NN.png
  std::string pattern_image;    ///< extrinsics/pattern.png
  std::string taught;           ///< extrinsics/taught.yaml {origin, on_x, in_xy}
  std::string laser_obs;        ///< laser/observations.yaml (least squares)
  std::string three_point_obs;  ///< laser_three_point/observations.yaml
  std::string fixture_intrinsics_dir;  ///< fixture camera, when the scene has fixtures (else empty)
  std::string fixture_pattern_image;
  std::string fixture_taught;
  double fixture_square = 0;
  std::string hand_eye_dir;     ///< view_NN.png, flange_poses.yaml, touched.yaml (fixture camera)
  double hand_eye_square = 0;
  std::string board;            ///< "9x6"
  double square = 0;
};

/// Writes the captures under `dir` (creates it; files atomic). Throws std::runtime_error when
/// a pose cannot be reached or a board view cannot be placed in the image.
CalibrationCaptureFiles writeCalibrationCaptures(const Scene& scene, const std::string& dir,
                                                 const CalibrationCaptureConfig& config = {});

}  // namespace cellsight
