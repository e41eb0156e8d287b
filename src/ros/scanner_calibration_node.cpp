// scanner_calibration: the calibration procedures as ROS services (the same core as the
// cellsight_calibrate tool). Requests carry the data (images, camera_info, poses); responses carry
// the result (camera_info or transform, residuals). Each result is also written atomically into
// ~calibration_dir (the folder calibration_publisher serves): on any failure the previous file
// stays as it was. With ~reload_publisher the calibration_publisher re-reads its folder after a
// successful calibration.
#include <ros/ros.h>
#include <sensor_msgs/image_encodings.h>
#include <std_srvs/Trigger.h>
#include <tf2_eigen/tf2_eigen.h>

#include <cctype>
#include <opencv2/imgproc.hpp>

#include "cellsight/CalibrateExtrinsics.h"
#include "cellsight/CalibrateIntrinsics.h"
#include "cellsight/CalibrateLaser.h"
#include "cellsight/scanner/calibrate.hpp"
#include "cellsight/common/calibration.hpp"
#include "cellsight/common/file_io.hpp"
#include "cellsight_ros/conversions.hpp"
#include "cellsight_ros/node.hpp"
#include "cellsight_ros/diagnostics.hpp"
#include "cellsight_ros/params.hpp"

namespace {

class ScannerCalibration {
 public:
  ScannerCalibration(ros::NodeHandle& nh, ros::NodeHandle& pnh)
      : diag_(nh, pnh, "scanner_calibration", "calibrations", 2.0) {
    cellsight_ros::param(pnh, "reload_publisher", reload_);
    cellsight_ros::param(pnh, "calibration_dir", calibration_dir_);
    reload_client_ = nh.serviceClient<std_srvs::Trigger>("calibration_publisher/reload");
    intrinsics_ = pnh.advertiseService("intrinsics", &ScannerCalibration::onIntrinsics, this);
    extrinsics_ = pnh.advertiseService("extrinsics", &ScannerCalibration::onExtrinsics, this);
    laser_ = pnh.advertiseService("laser", &ScannerCalibration::onLaser, this);
  }

 private:
  template <typename Res, typename F>
  bool guarded(Res& res, F&& f) {
    try {
      f();
      res.status = Res::OK;
      if (reload_) {
        std_srvs::Trigger t;
        if (reload_client_.call(t) && !t.response.success) res.message += "; reload refused: " + t.response.message;
      }
      ROS_INFO("scanner_calibration: %s", res.message.c_str());
      diag_.processed();
      diag_.set("last calibration", res.message);
    } catch (const std::exception& e) {
      res.status = Res::FAILED;
      res.message = std::string("calibration failed, previous file kept: ") + e.what();
      ROS_ERROR("scanner_calibration: %s", res.message.c_str());
      diag_.dropped("calibration failed");
      diag_.set("last calibration", res.message);
    }
    return true;
  }

  static cellsight::ChessboardSpec board(int cols, int rows, double square) {
    if (cols < 2 || rows < 2 || cols > 200 || rows > 200 || !(square >= 1e-4 && square <= 1.0)) {
      throw std::invalid_argument("board needs 2x2 to 200x200 inner corners and a square size of 0.1 mm to 1 m (metres), "
                                  "got " + std::to_string(cols) + "x" + std::to_string(rows) + ", " + std::to_string(square));
    }
    return {{cols, rows}, square};
  }

  /// A camera or frame name from a request as the file name and YAML it becomes: ROS naming
  /// (letters, digits, '_', '/'-separated, each part starting with a letter; no leading '/'),
  /// at most 64 characters; throws naming `what` otherwise.
  static const std::string& checkedName(const std::string& what, const std::string& name) {
    bool ok = !name.empty() && name.size() <= 64 && name.front() != '/' && name.back() != '/';
    for (size_t i = 0; ok && i < name.size(); ++i) {
      const char c = name[i];
      const bool starts = i == 0 || name[i - 1] == '/';
      ok = starts ? std::isalpha(static_cast<unsigned char>(c)) : (std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '/');
    }
    if (!ok)
      throw std::invalid_argument(what + " '" + name.substr(0, 64) +
                                  "' is not a ROS name (letters, digits, '_', '/'-separated parts starting with a letter)");
    return name;
  }

  /// The request's image as 8-bit grey (mono8 as it is; rgb8/bgr8 converted); throws naming it.
  static cv::Mat grey(const sensor_msgs::Image& image, const std::string& what) {
    cv::Mat view;
    try {
      view = cellsight_ros::fromImageMsg(image);
    } catch (const std::invalid_argument& e) {
      throw std::invalid_argument(what + ": unusable image: " + e.what());
    }
    cv::Mat grey;
    if (view.channels() == 1) {
      grey = view.clone();
    } else {
      cv::cvtColor(view, grey, image.encoding == sensor_msgs::image_encodings::RGB8 ? cv::COLOR_RGB2GRAY : cv::COLOR_BGR2GRAY);
    }
    return grey;
  }

  /// The file of ~calibration_dir that already calibrates `child_frame` (so the new result
  /// replaces it), else <~calibration_dir>/<child_frame>.yaml; "" when the node has no folder.
  std::string transformFileFor(const std::string& child_frame) const {
    if (calibration_dir_.empty()) return "";
    try {
      for (const auto& [file, cal] : cellsight::loadCalibrationFolder(calibration_dir_).transforms)
        if (cal.child_frame == child_frame) return file;
    } catch (const std::exception&) {
      // a missing or unreadable folder: the new file goes in under the frame's name
    }
    return fileFor(child_frame);
  }

  /// <~calibration_dir>/<name>.yaml (the folder made when missing), or "" when the node has no
  /// folder (results only returned).
  std::string fileFor(const std::string& name) const {
    if (calibration_dir_.empty()) return "";
    cellsight::makeDirs(calibration_dir_);
    std::string base = name;
    for (char& ch : base)
      if (ch == '/') ch = '_';
    return calibration_dir_ + "/" + base + ".yaml";
  }

  static geometry_msgs::TransformStamped toMsg(const cellsight::TransformCalibration& c) {
    geometry_msgs::TransformStamped t = tf2::eigenToTransform(c.T_parent_child);
    t.header.frame_id = c.parent_frame;
    t.header.stamp = ros::Time::now();
    t.child_frame_id = c.child_frame;
    return t;
  }

  bool onIntrinsics(cellsight::CalibrateIntrinsics::Request& req, cellsight::CalibrateIntrinsics::Response& res) {
    return guarded(res, [&] {
      const std::string camera_name = req.camera_name.empty() ? "scanner_camera" : checkedName("camera_name", req.camera_name);
      const cellsight::ChessboardSpec spec = board(req.board_cols, req.board_rows, req.square_size);
      if (req.images.empty()) throw std::invalid_argument("no images in the request");
      std::vector<std::pair<std::string, cv::Mat>> views;
      for (size_t i = 0; i < req.images.size(); ++i) {
        const std::string name = "image " + std::to_string(i);
        views.emplace_back(name, grey(req.images[i], name));
      }
      auto r = cellsight::calibrateIntrinsics(views, spec,
                                              cellsight::parseDistortionModel(req.model.empty() ? "full" : req.model),
                                              req.fix_aspect_ratio);
      r.camera.camera_name = camera_name;
      res.file = fileFor(r.camera.camera_name);
      if (!res.file.empty()) cellsight::saveCameraInfoYaml(res.file, r.camera);
      res.camera_info = cellsight_ros::toCameraInfo(r.camera, req.images.front().header.frame_id, ros::Time::now());
      res.rms_px = r.rms_px;
      res.views_used = static_cast<uint32_t>(r.used.size());
      res.per_view_rms_px = r.per_view_rms_px;
      res.message = "intrinsics from " + std::to_string(r.used.size()) + " of " + std::to_string(views.size()) +
                    " views, RMS " + std::to_string(r.rms_px) + " px" +
                    (res.file.empty() ? " (not written: ~calibration_dir is not set)" : ", written to " + res.file);
      for (const auto& v : r.high_rms_views) res.message += "; high RMS: " + v;
      for (const auto& w : r.warnings) {
        res.message += "; warning: " + w;
        ROS_WARN("scanner_calibration: intrinsics: %s", w.c_str());
      }
    });
  }

  bool onExtrinsics(cellsight::CalibrateExtrinsics::Request& req, cellsight::CalibrateExtrinsics::Response& res) {
    return guarded(res, [&] {
      cellsight::TransformCalibration c;
      c.parent_frame = checkedName("parent_frame", req.parent_frame.empty() ? "base_link" : req.parent_frame);
      c.child_frame = checkedName("child_frame", !req.child_frame.empty()               ? req.child_frame
                                                 : !req.camera_info.header.frame_id.empty() ? req.camera_info.header.frame_id
                                                                                            : "scanner_camera_optical");
      if (c.child_frame == c.parent_frame) throw std::invalid_argument("child_frame and parent_frame are both '" + c.child_frame + "'");
      const cellsight::CameraIntrinsics cam = cellsight_ros::fromCameraInfo(req.camera_info);
      auto p = [](const geometry_msgs::Point& q) { return Eigen::Vector3d(q.x, q.y, q.z); };
      for (const auto* q : {&req.origin, &req.on_x, &req.in_xy})
        if (!p(*q).allFinite()) throw std::invalid_argument("a taught point is not finite");
      const auto r = cellsight::calibrateExtrinsics(grey(req.image, "image"),
                                                    board(req.board_cols, req.board_rows, req.square_size), cam,
                                                    cellsight::frameFromThreePoints(p(req.origin), p(req.on_x), p(req.in_xy)));
      c.T_parent_child = r.T_base_camera;
      c.residual_rms = r.rms_px;
      c.method = "pattern PnP + taught pattern frame (residual: reprojection RMS px)";
      c.date = cellsight::isoDateNow();
      res.file = transformFileFor(c.child_frame);
      if (!res.file.empty()) cellsight::saveTransformCalibration(res.file, c);
      res.transform = toMsg(c);
      res.rms_px = r.rms_px;
      res.message = "camera pose " + c.parent_frame + " -> " + c.child_frame + ", RMS " + std::to_string(r.rms_px) +
                    " px" + (res.file.empty() ? " (not written: ~calibration_dir is not set)" : ", written to " + res.file);
    });
  }

  bool onLaser(cellsight::CalibrateLaser::Request& req, cellsight::CalibrateLaser::Response& res) {
    return guarded(res, [&] {
      cellsight::TransformCalibration c;
      c.parent_frame = checkedName("flange_frame", req.flange_frame.empty() ? "flange" : req.flange_frame);
      c.child_frame = checkedName("laser_frame", req.laser_frame.empty() ? "laser" : req.laser_frame);
      if (c.child_frame == c.parent_frame) throw std::invalid_argument("laser_frame and flange_frame are both '" + c.child_frame + "'");
      const size_t n = req.images.size();
      if (n == 0) throw std::invalid_argument("no observations in the request");
      if (req.flange_poses.size() != n || req.plane_z.size() != n || (!req.block_z.empty() && req.block_z.size() != n)) {
        throw std::invalid_argument("images, flange_poses, plane_z (and block_z when given) must have one entry per "
                                    "observation (" + std::to_string(n) + " images)");
      }
      const cellsight::CameraIntrinsics cam = cellsight_ros::fromCameraInfo(req.camera_info);
      const Eigen::Isometry3d T_base_camera = cellsight_ros::fromTransformMsg(req.camera_pose);
      std::vector<cellsight::LaserObservation> obs(n);
      for (size_t i = 0; i < n; ++i) {
        obs[i].image = grey(req.images[i], "observation " + std::to_string(i));
        try {
          obs[i].T_base_flange = cellsight_ros::fromPoseMsg(req.flange_poses[i]);
        } catch (const std::exception& e) {
          throw std::invalid_argument("flange pose " + std::to_string(i) + ": " + e.what());
        }
        obs[i].plane_z = req.plane_z[i];
        obs[i].block_z = req.block_z.empty() ? 0.0 : req.block_z[i];
      }
      const std::string method = req.method.empty() ? "lsq" : req.method;
      cellsight::LaserCalibrationResult r;
      if (method == "lsq") {
        r = cellsight::calibrateLaserLeastSquares(obs, cam, T_base_camera, {});
      } else if (method == "three_point") {
        r = cellsight::calibrateLaserThreePoint(obs.front(), cam, T_base_camera, {});
      } else {
        throw std::invalid_argument("method must be lsq or three_point");
      }
      c.T_parent_child = r.T_flange_laser;
      c.residual_rms = r.rms_m;
      c.method = method + " light-sheet calibration (residual: m)";
      c.date = cellsight::isoDateNow();
      res.file = transformFileFor(c.child_frame);
      if (!res.file.empty()) cellsight::saveTransformCalibration(res.file, c);
      res.transform = toMsg(c);
      res.rms_mm = r.rms_m * 1e3;
      res.points = static_cast<uint32_t>(r.points);
      res.spread_ratio = r.spread_ratio;
      res.message = "light sheet from " + std::to_string(r.points) + " points, RMS " + std::to_string(res.rms_mm) +
                    " mm" + (res.file.empty() ? " (not written: ~calibration_dir is not set)" : ", written to " + res.file);
    });
  }

  std::string calibration_dir_;
  bool reload_ = false;
  cellsight_ros::NodeDiagnostics diag_;
  ros::ServiceClient reload_client_;
  ros::ServiceServer intrinsics_, extrinsics_, laser_;
};

}  // namespace

CELLSIGHT_NODE(ScannerCalibration, "scanner_calibration", 1)
