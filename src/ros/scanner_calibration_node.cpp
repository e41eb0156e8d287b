// scanner_calibration: the calibration procedures as ROS services (the same core as the
// cellsight_calibrate tool). Each writes its YAML atomically: on any failure the previous file
// stays as it was. With ~reload_publisher the calibration_publisher re-reads its folder after a
// successful calibration.
#include <ros/ros.h>
#include <std_srvs/Trigger.h>

#include <opencv2/imgcodecs.hpp>

#include "cellsight/CalibrateExtrinsics.h"
#include "cellsight/CalibrateIntrinsics.h"
#include "cellsight/CalibrateLaser.h"
#include "cellsight/calibrate.hpp"
#include "cellsight/calibration.hpp"
#include "cellsight_ros/node.hpp"
#include "cellsight_ros/params.hpp"

namespace {

class ScannerCalibration {
 public:
  ScannerCalibration(ros::NodeHandle& nh, ros::NodeHandle& pnh) {
    cellsight_ros::param(pnh, "reload_publisher", reload_);
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
    } catch (const std::exception& e) {
      res.status = Res::FAILED;
      res.message = std::string("calibration failed, previous file kept: ") + e.what();
      ROS_ERROR("scanner_calibration: %s", res.message.c_str());
    }
    return true;
  }

  static cellsight::ChessboardSpec board(int cols, int rows, double square) {
    if (cols < 2 || rows < 2 || !(square > 0)) {
      throw std::invalid_argument("board needs >= 2x2 inner corners and a square size > 0 (metres)");
    }
    return {{cols, rows}, square};
  }

  bool onIntrinsics(cellsight::CalibrateIntrinsics::Request& req, cellsight::CalibrateIntrinsics::Response& res) {
    return guarded(res, [&] {
      if (req.output_file.empty()) throw std::invalid_argument("output_file is empty");
      auto r = cellsight::calibrateIntrinsics(cellsight::listImages(req.images),
                                              board(req.board_cols, req.board_rows, req.square_size),
                                              cellsight::parseDistortionModel(req.model.empty() ? "full" : req.model),
                                              req.fix_aspect_ratio);
      r.camera.camera_name = req.camera_name.empty() ? "scanner_camera" : req.camera_name;
      cellsight::saveCameraInfoYaml(req.output_file, r.camera);
      res.rms_px = r.rms_px;
      res.views_used = static_cast<uint32_t>(r.used.size());
      res.message = "intrinsics from " + std::to_string(r.used.size()) + " views, RMS " + std::to_string(r.rms_px) +
                    " px, written to " + req.output_file;
    });
  }

  bool onExtrinsics(cellsight::CalibrateExtrinsics::Request& req, cellsight::CalibrateExtrinsics::Response& res) {
    return guarded(res, [&] {
      const auto cam = cellsight::loadCameraInfoYaml(req.camera_file);
      const cv::Mat grey = cv::imread(req.image, cv::IMREAD_GRAYSCALE);
      if (grey.empty()) throw std::runtime_error(req.image + ": cannot read the image");
      auto p = [](const geometry_msgs::Point& q) { return Eigen::Vector3d(q.x, q.y, q.z); };
      const auto r = cellsight::calibrateExtrinsics(grey, board(req.board_cols, req.board_rows, req.square_size), cam,
                                                    cellsight::frameFromThreePoints(p(req.origin), p(req.on_x), p(req.in_xy)));
      cellsight::TransformCalibration c;
      c.parent_frame = req.parent_frame.empty() ? "base_link" : req.parent_frame;
      c.child_frame = req.child_frame.empty() ? "scanner_camera_optical" : req.child_frame;
      c.T_parent_child = r.T_base_camera;
      c.residual_rms = r.rms_px;
      c.method = "pattern PnP + taught pattern frame (residual: reprojection RMS px)";
      c.date = cellsight::isoDateNow();
      cellsight::saveTransformCalibration(req.output_file, c);
      res.rms_px = r.rms_px;
      res.message = "camera pose written to " + req.output_file;
    });
  }

  bool onLaser(cellsight::CalibrateLaser::Request& req, cellsight::CalibrateLaser::Response& res) {
    return guarded(res, [&] {
      const auto cam = cellsight::loadCameraInfoYaml(req.camera_file);
      const auto pose = cellsight::loadTransformCalibration(req.camera_pose_file);
      const auto obs = cellsight::loadLaserObservations(req.observations_file);
      const std::string method = req.method.empty() ? "lsq" : req.method;
      cellsight::LaserCalibrationResult r;
      if (method == "lsq") {
        r = cellsight::calibrateLaserLeastSquares(obs, cam, pose.T_parent_child, {});
      } else if (method == "three_point") {
        r = cellsight::calibrateLaserThreePoint(obs.front(), cam, pose.T_parent_child, {});
      } else {
        throw std::invalid_argument("method must be lsq or three_point");
      }
      cellsight::TransformCalibration c;
      c.parent_frame = req.flange_frame.empty() ? "flange" : req.flange_frame;
      c.child_frame = req.laser_frame.empty() ? "laser" : req.laser_frame;
      c.T_parent_child = r.T_flange_laser;
      c.residual_rms = r.rms_m;
      c.method = method + " light-sheet calibration (residual: m)";
      c.date = cellsight::isoDateNow();
      cellsight::saveTransformCalibration(req.output_file, c);
      res.rms_mm = r.rms_m * 1e3;
      res.points = static_cast<uint32_t>(r.points);
      res.message = "light sheet from " + std::to_string(r.points) + " points, RMS " + std::to_string(res.rms_mm) +
                    " mm, written to " + req.output_file;
    });
  }

  bool reload_ = false;
  ros::ServiceClient reload_client_;
  ros::ServiceServer intrinsics_, extrinsics_, laser_;
};

}  // namespace

int main(int argc, char** argv) {
  return cellsight_ros::runNode<ScannerCalibration>(argc, argv, "scanner_calibration");
}
