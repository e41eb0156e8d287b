// Calibration procedures of the scanner (thesis §1): camera intrinsics from chessboard images
// (Zhang), camera → user/base frame from one pattern image and a taught pattern frame, and the
// light sheet → flange from observed lines (least squares over many poses, or the thesis's
// plate-and-gauge-block three-point method).
#pragma once
#include <Eigen/Geometry>
#include <opencv2/core.hpp>
#include <string>
#include <vector>

#include "cellsight/common/camera_model.hpp"
#include "cellsight/scanner/line_extraction.hpp"
#include "cellsight/common/plane.hpp"

namespace cellsight {

/// A calibration target (the name is historical: it covers every pattern kind).
///  - chessboard: `inner_corners` per row, per column; `square_size`;
///  - circles / asymmetric circles (OpenCV's layouts): centres per row, per column in
///    `inner_corners`; `square_size` = centre spacing (asymmetric: centre (i, j) at
///    ((2j + i mod 2)·s, i·s), as OpenCV's calibration sample);
///  - ChArUco: squares per row, per column in `inner_corners`, `square_size`, `marker_size`,
///    `dictionary` (e.g. "4x4_50", "5x5_100", "6x6_250"); partial views give the corners they show.
struct ChessboardSpec {
  enum class Kind { kChessboard, kCircles, kAsymmetricCircles, kCharuco };
  /// Chessboard corner refinement: kAdaptive: cornerSubPix with a window from the measured square
  /// size in pixels; kFixed: cornerSubPix with OpenCV's sample winSize (11, 11), a 23 × 23 window;
  /// kSectorBased: findChessboardCornersSB's own.
  enum class Refinement { kAdaptive, kFixed, kSectorBased };
  cv::Size inner_corners{9, 6};  ///< corners per row, per column (see above for other kinds)
  double square_size = 0.025;    ///< metres
  Kind kind = Kind::kChessboard;
  Refinement refinement = Refinement::kAdaptive;
  double marker_size = 0;        ///< ChArUco marker side, metres
  std::string dictionary = "4x4_50";

  static Kind parseKind(const std::string& name);              ///< chessboard|circles|acircles|charuco
  static Refinement parseRefinement(const std::string& name);  ///< adaptive|fixed|sb
};

/// Throws std::invalid_argument naming the choices if `name` is no ArUco dictionary we know.
void checkArucoDictionary(const std::string& name);

/// One view's detected pattern: image points, their board coordinates (metres, z = 0) and ids
/// (the index of each point on the full board; all of them unless the view is partial).
struct PatternView {
  std::vector<cv::Point2f> image;
  std::vector<cv::Point3f> object;
  std::vector<int> ids;
};

enum class DistortionModel {
  kK1,    ///< the thesis: radial r² term only
  kFull,  ///< OpenCV's five terms k1 k2 p1 p2 k3
};
DistortionModel parseDistortionModel(const std::string& name);  ///< "k1" | "full"

struct IntrinsicsOptions {
  DistortionModel model = DistortionModel::kFull;
  bool fix_aspect_ratio = false;  ///< fx = fy
  /// Views whose reprojection RMS exceeds max(this, 3 × the median view's) are reported in
  /// `high_rms_views`; with `drop_high_rms_views` they are dropped and the camera recalibrated.
  double view_rms_threshold_px = 1.0;
  bool drop_high_rms_views = false;
};

struct IntrinsicsResult {
  CameraIntrinsics camera;
  double rms_px = 0;                    ///< reprojection RMS over all points of the used views
  std::vector<double> per_view_rms_px;  ///< for the used images
  std::vector<std::string> used, rejected;  ///< rejected: no board found (or unreadable)
  std::vector<PatternView> detections;  ///< per used image: what was detected
  std::vector<std::string> high_rms_views;  ///< "name (x.xx px)", dropped if asked
  std::vector<std::string> dropped;         ///< views dropped for their RMS
  std::vector<std::string> warnings;        ///< the result looks suspect: why, and what to do
};

/// Finds the chessboard corners (sub-pixel) in one grey image; false if not found.
bool findChessboard(const cv::Mat& grey, const ChessboardSpec& board, std::vector<cv::Point2f>& corners);
/// Finds any pattern kind (chessboard, circle grids, ChArUco — partial views allowed for
/// ChArUco, at least 6 corners); false if not found.
bool detectPattern(const cv::Mat& grey, const ChessboardSpec& board, PatternView& view);

/// Zhang's calibration over images (files); throws std::runtime_error if fewer than 3 views
/// show the board, std::invalid_argument if the images differ in size.
IntrinsicsResult calibrateIntrinsics(const std::vector<std::string>& image_files, const ChessboardSpec& board,
                                     const IntrinsicsOptions& options);
IntrinsicsResult calibrateIntrinsics(const std::vector<std::string>& image_files, const ChessboardSpec& board,
                                     DistortionModel model, bool fix_aspect_ratio = false);
/// The same over images in memory (grey, 8-bit), each with a name for the report; an empty image
/// is reported as unreadable.
IntrinsicsResult calibrateIntrinsics(const std::vector<std::pair<std::string, cv::Mat>>& views,
                                     const ChessboardSpec& board, const IntrinsicsOptions& options);
IntrinsicsResult calibrateIntrinsics(const std::vector<std::pair<std::string, cv::Mat>>& views,
                                     const ChessboardSpec& board, DistortionModel model,
                                     bool fix_aspect_ratio = false);
/// Warnings for a calibration that looks suspect (high RMS, focal length far from the image
/// size's usual range, fx ≠ fy, principal point far off centre, strong distortion with few views).
std::vector<std::string> intrinsicsWarnings(const IntrinsicsResult& r, DistortionModel model);

/// A frame taught by three points (thesis: robot with a calibrated pointer): origin, a point on
/// +x, a point in the xy plane (y > 0 side). Throws std::invalid_argument if degenerate.
Eigen::Isometry3d frameFromThreePoints(const Eigen::Vector3d& origin, const Eigen::Vector3d& on_x,
                                       const Eigen::Vector3d& in_xy);

struct ExtrinsicsResult {
  Eigen::Isometry3d T_base_camera = Eigen::Isometry3d::Identity();
  Eigen::Isometry3d T_camera_pattern = Eigen::Isometry3d::Identity();
  double rms_px = 0;
};

/// Camera pose in the base (or user) frame from one image of the pattern whose frame is known
/// there (T_base_pattern: pattern origin at the first inner corner, x along the rows, z out
/// of the board). Throws std::runtime_error if the board is not found.
ExtrinsicsResult calibrateExtrinsics(const cv::Mat& grey, const ChessboardSpec& board,
                                     const CameraIntrinsics& camera, const Eigen::Isometry3d& T_base_pattern);

/// One view of the laser line on a plane of known height (base frame), with the flange pose.
struct LaserObservation {
  cv::Mat image;
  Eigen::Isometry3d T_base_flange = Eigen::Isometry3d::Identity();
  double plane_z = 0;  ///< height of the surface the line falls on (plate / table)
  double block_z = 0;  ///< three-point method: height of the gauge block's top face
};

struct LaserCalibrationResult {
  Eigen::Isometry3d T_flange_laser = Eigen::Isometry3d::Identity();  ///< sheet = plane y = 0
  Plane plane_flange;             ///< the sheet in the flange frame
  double rms_m = 0;               ///< RMS point-to-sheet distance of the observations
  size_t points = 0;
  double spread_ratio = 0;        ///< 2nd / 1st singular value of the points: ≪ 1 is ill-conditioned
};

/// Least squares over many observations (plates at several heights and/or several robot
/// poses): every line point is cut with its known plane, taken into the flange frame, and one
/// plane is fitted. Throws std::runtime_error if the points do not span a plane.
LaserCalibrationResult calibrateLaserLeastSquares(const std::vector<LaserObservation>& obs,
                                                  const CameraIntrinsics& camera,
                                                  const Eigen::Isometry3d& T_base_camera,
                                                  const LineExtractionConfig& line);

/// The thesis's method: one view of the line across the plate and a gauge block. The line's two
/// longest straight segments are taken as plate (lower) and block (upper); two points on the
/// plate segment and one on the block give the sheet.
LaserCalibrationResult calibrateLaserThreePoint(const LaserObservation& obs, const CameraIntrinsics& camera,
                                                const Eigen::Isometry3d& T_base_camera,
                                                const LineExtractionConfig& line);

/// Observations file: {observations: [{image, flange_pose, plane_z, block_z}]}, image paths
/// relative to the file. Throws ConfigError naming the file and key.
std::vector<LaserObservation> loadLaserObservations(const std::string& path);

/// Image files of folders (sorted .png/.jpg/.jpeg) and plain files, in order.
std::vector<std::string> listImages(const std::vector<std::string>& folders_or_files);

/// Builds T_flange_laser for a sheet given in the flange frame: origin at the flange origin's
/// projection on the sheet, z towards `towards` (projected into the sheet), y = sheet normal.
Eigen::Isometry3d laserFrameFromPlane(const Plane& plane_flange, const Eigen::Vector3d& towards);

}  // namespace cellsight
