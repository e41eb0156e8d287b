// triangulation: scanner images + the light sheet at their stamps → one profile per frame
// (scan/profile, base frame) and the accumulated scan. scan/finish applies the statistical
// outlier filter, the workspace crop and normals, saves PLY/PCD and publishes scan/cloud with
// scan/light_sweep and scan/pass (the cycle and role the request gives) at its stamp.
#include <dynamic_reconfigure/server.h>
#include <image_transport/image_transport.h>
#include <image_transport/subscriber_filter.h>
#include <message_filters/subscriber.h>
#include <message_filters/time_synchronizer.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <algorithm>
#include <condition_variable>
#include <deque>
#include <mutex>

#include "cellsight/FinishScan.h"
#include "cellsight/CyclePass.h"
#include "cellsight/common/scan_cloud.hpp"
#include "cellsight/scanner/scan_pipeline.hpp"
#include "cellsight_ros/conversions.hpp"
#include "cellsight_ros/node.hpp"
#include "cellsight/ScannerLineConfig.h"
#include "cellsight_ros/diagnostics.hpp"
#include "cellsight/common/file_io.hpp"
#include "cellsight_ros/params.hpp"
#include "cellsight_ros/scan_messages.hpp"

namespace {

// Frames waiting to be processed: the robot does not wait for the PC (a cycle's next pass scans
// while the last is located and planned on), so a busy PC must queue a pass's frames, not drop them.
constexpr uint32_t kFrameQueue = 60;

class Triangulation {
 public:
  Triangulation(ros::NodeHandle& nh, ros::NodeHandle& pnh)
      : diag_(nh, pnh, "triangulation", "frames"), listener_(buffer_), it_(nh), image_sub_(it_, "scanner_camera/image_raw", kFrameQueue),
        plane_sub_(nh, "scan/laser_plane", kFrameQueue), sync_(image_sub_, plane_sub_, 2 * kFrameQueue) {
    // One strictly validated settings file (config/scanner.yaml): a typo stops the node at start.
    const std::string settings_file = cellsight_ros::requireParam<std::string>(
        pnh, "settings_file", "scanner settings YAML, e.g. $(find cellsight)/config/scanner.yaml");
    settings_ = cellsight::loadScannerSettings(settings_file);
    line_ = settings_.line;
    cellsight_ros::param(pnh, "base_frame", base_frame_);
    cellsight_ros::param(pnh, "laser_frame", laser_frame_);
    // scan/finish writes only here: a request names a file, never a path
    cellsight_ros::param(pnh, "output_dir", output_dir_);
    if (output_dir_.empty()) output_dir_ = cellsight_ros::rosHomePath("cellsight/scans");
    info_sub_ = nh.subscribe("scanner_camera/camera_info", 5, &Triangulation::onInfo, this);
    sync_.registerCallback(&Triangulation::onFrame, this);
    profile_pub_ = nh.advertise<sensor_msgs::PointCloud2>("scan/profile", 20);
    cloud_pub_ = nh.advertise<sensor_msgs::PointCloud2>("scan/cloud", 1, true);
    sweep_pub_ = nh.advertise<cellsight::LaserSweep>("scan/light_sweep", 1, true);
    pass_pub_ = nh.advertise<cellsight::CyclePass>("scan/pass", 4, true);
    reset_srv_ = nh.advertiseService("scan/reset", &Triangulation::onReset, this);
    finish_srv_ = nh.advertiseService("scan/finish", &Triangulation::onFinish, this);
    // the settings file's thresholds are the starting values of ~ (rqt_reconfigure)
    reconfigure_ = std::make_unique<dynamic_reconfigure::Server<cellsight::ScannerLineConfig>>(reconfigure_mutex_, pnh);
    cellsight::ScannerLineConfig start;
    cellsight::copyLineThresholds(cellsight::lineThresholdsOf(line_), &start);
    reconfigure_->updateConfig(start);
    reconfigure_->setCallback([this](cellsight::ScannerLineConfig& c, uint32_t) { onReconfigure(c); });
  }

 private:
  /// New thresholds from dynamic_reconfigure, checked like config/scanner.yaml; refused ones are
  /// logged and the running values sent back.
  void onReconfigure(cellsight::ScannerLineConfig& c) {
    const cellsight::LineThresholds t{c.min_contrast, c.threshold_fraction, c.max_run, c.secondary_peak_ratio,
                                      c.min_segment, c.segment_max_jump};
    const auto bad = cellsight::checkLineThresholds(t);
    std::lock_guard<std::mutex> lock(mutex_);
    if (!bad.first.empty()) {
      ROS_ERROR("triangulation: reconfigure refused: %s %s; the running thresholds stay", bad.first.c_str(),
                bad.second.c_str());
      cellsight::copyLineThresholds(cellsight::lineThresholdsOf(line_), &c);
      return;
    }
    cellsight::copyLineThresholds(t, &line_);
    ROS_INFO("triangulation: line thresholds now min_contrast %.1f, threshold_fraction %.2f, max_run %d, "
             "secondary_peak_ratio %.2f, min_segment %d, segment_max_jump %.2f",
             t.min_contrast, t.threshold_fraction, t.max_run, t.secondary_peak_ratio, t.min_segment, t.segment_max_jump);
  }

  void onInfo(const sensor_msgs::CameraInfoConstPtr& msg) {
    cellsight::CameraIntrinsics K;
    try {
      K = cellsight_ros::fromCameraInfo(*msg);
    } catch (const std::exception& e) {
      ROS_ERROR_THROTTLE(5.0, "triangulation: unusable camera_info: %s", e.what());
      return;
    }
    std::unique_lock<std::mutex> lock(mutex_);
    if (map_ && map_->camera().fx == K.fx && map_->camera().fy == K.fy && map_->camera().cx == K.cx &&
        map_->camera().cy == K.cy && map_->camera().dist == K.dist && map_->camera().width == K.width &&
        map_->camera().height == K.height)
      return;
    try {
      map_ = std::make_shared<cellsight::UndistortionMap>(K);
    } catch (const std::exception& e) {  // std::bad_alloc included: the node keeps its old map
      ROS_ERROR_THROTTLE(5.0, "triangulation: cannot build the undistortion map for %dx%d: %s", K.width, K.height, e.what());
      return;
    }
    ROS_INFO("triangulation: camera intrinsics %dx%d fx %.1f from camera_info", K.width, K.height, K.fx);
    // frames that came before the first camera_info (the camera publishes both at once, but
    // the two topics race at start-up) are processed now rather than lost
    std::deque<Frame> held;
    held.swap(held_);
    lock.unlock();
    for (const auto& f : held) onFrame(f.first, f.second);
  }

  void onFrame(const sensor_msgs::ImageConstPtr& image, const cellsight::LaserPlaneStampedConstPtr& plane_msg) {
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!map_) {
        if (held_.size() >= kMaxHeldFrames) {
          ROS_WARN("triangulation: still no camera_info on scanner_camera/camera_info after %zu frames: "
                   "the oldest is dropped; is the camera driver publishing it?", held_.size());
          held_.pop_front();
          diag_.dropped("no camera_info");
          ++frames_;
          cv_.notify_all();
        }
        ROS_WARN_THROTTLE(5.0, "triangulation: no camera_info yet on scanner_camera/camera_info: frames are held "
                               "until it arrives");
        held_.emplace_back(image, plane_msg);
        return;
      }
    }
    try {
      processFrame(image, plane_msg);
    } catch (const std::exception& e) {
      ROS_ERROR_THROTTLE(2.0, "triangulation: frame at %.6f dropped: %s", image->header.stamp.toSec(), e.what());
      diag_.dropped("processing error");
    }
    std::lock_guard<std::mutex> lock(mutex_);
    ++frames_;
    cv_.notify_all();
  }

  void processFrame(const sensor_msgs::ImageConstPtr& image, const cellsight::LaserPlaneStampedConstPtr& plane_msg) {
    const ros::WallTime t0 = ros::WallTime::now();
    std::shared_ptr<const cellsight::UndistortionMap> map;
    cellsight::LineExtractionConfig lc;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      map = map_;
      lc = line_;  // the thresholds may change (dynamic_reconfigure) between frames
    }
    // not null: onFrame holds frames back until the first camera_info, and map_ is never reset
    if (static_cast<int>(image->width) != map->camera().width || static_cast<int>(image->height) != map->camera().height) {
      ROS_ERROR_THROTTLE(5.0, "triangulation: image %ux%u does not match camera_info %dx%d: frame dropped",
                         image->width, image->height, map->camera().width, map->camera().height);
      diag_.dropped("image size differs from camera_info");
      return;
    }
    if (plane_msg->header.frame_id != image->header.frame_id) {
      ROS_ERROR_THROTTLE(5.0, "triangulation: laser plane in '%s' but image in '%s': frame dropped",
                         plane_msg->header.frame_id.c_str(), image->header.frame_id.c_str());
      diag_.dropped("laser plane and image in different frames");
      return;
    }
    cv::Mat img;
    try {
      img = cellsight_ros::fromImageMsg(*image);
    } catch (const std::invalid_argument& e) {
      ROS_ERROR_THROTTLE(5.0, "triangulation: unusable image: %s: frame dropped", e.what());
      diag_.dropped("unusable image");
      return;
    }
    lc = cellsight_ros::lineConfigFor(image->encoding, lc);
    geometry_msgs::TransformStamped T;
    try {
      T = buffer_.lookupTransform(base_frame_, image->header.frame_id, image->header.stamp, ros::Duration(0.2));
    } catch (const tf2::TransformException& e) {
      ROS_ERROR_THROTTLE(2.0, "triangulation: frame at %.6f dropped: no %s -> %s at its stamp: %s",
                         image->header.stamp.toSec(), base_frame_.c_str(), image->header.frame_id.c_str(), e.what());
      diag_.dropped("no camera transform at the image stamp");
      return;
    }
    const Eigen::Isometry3d T_base_camera = cellsight_ros::fromTransformMsg(T.transform);
    // where the sheet came from (the matcher's illumination test): the laser frame at this stamp
    bool lit = false;
    Eigen::Isometry3d T_base_laser;
    try {
      T_base_laser = cellsight_ros::fromTransformMsg(
          buffer_.lookupTransform(base_frame_, laser_frame_, image->header.stamp, ros::Duration(0.05)).transform);
      lit = true;
    } catch (const tf2::TransformException& e) {
      ROS_WARN_THROTTLE(5.0, "triangulation: no %s -> %s at %.6f (%s): this frame is left out of scan/light_sweep",
                        base_frame_.c_str(), laser_frame_.c_str(), image->header.stamp.toSec(), e.what());
    }
    const cellsight::Plane plane = cellsight_ros::fromPlaneMsg(*plane_msg);
    cellsight::LineExtractionStats st;
    cellsight::ScanCloud profile;
    profile.frame_id = base_frame_;
    const size_t found = cellsight::addFrameProfile(img, plane, T_base_camera, *map, lc, settings_.triangulation, profile, &st);
    profile_pub_.publish(cellsight_ros::toCloudMsg(profile, image->header.stamp));
    if (found == 0) {
      ROS_DEBUG("triangulation: no line in frame %.6f (%d columns without a line, %d ambiguous)",
                image->header.stamp.toSec(), st.no_line, st.ambiguous);
    }
    diag_.processed((ros::WallTime::now() - t0).toSec());
    std::lock_guard<std::mutex> lock(mutex_);
    // the newest frame's camera centre (the normals' viewpoint); profiles kept by stamp, so the
    // scan's point order does not depend on which callback thread finished first
    if (image->header.stamp >= last_stamp_) {
      last_stamp_ = image->header.stamp;
      camera_center_ = T_base_camera.translation().cast<float>();
    }
    profiles_.emplace_back(image->header.stamp, std::move(profile));
    if (lit) sweep_.emplace_back(image->header.stamp, T_base_laser);
  }

  /// The scan so far: every frame's profile in stamp order (mutex_ held).
  cellsight::ScanCloud joinedProfiles() {
    std::stable_sort(profiles_.begin(), profiles_.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    cellsight::ScanCloud scan;
    scan.frame_id = base_frame_;
    size_t n = 0;
    for (const auto& f : profiles_) n += f.second.size();
    scan.points.reserve(n);  // one allocation per scan, not a growing one
    scan.intensity.reserve(n);
    for (const auto& [stamp, p] : profiles_)
      for (size_t i = 0; i < p.size(); ++i) scan.append(p.points[i], p.intensity[i]);
    return scan;
  }

  bool onReset(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
    std::lock_guard<std::mutex> lock(mutex_);
    std::vector<std::pair<ros::Time, cellsight::ScanCloud>>().swap(profiles_);  // memory back, not kept
    frames_ = 0;
    last_stamp_ = ros::Time();
    held_.clear();
    sweep_.clear();
    res.success = true;
    res.message = "scan cleared";
    return true;
  }

  bool onFinish(cellsight::FinishScan::Request& req, cellsight::FinishScan::Response& res) {
    if (req.role > cellsight::CyclePass::REFINE || (req.role != cellsight::CyclePass::DETECT && req.cycle_id.empty())) {
      res.status = cellsight::FinishScan::Response::INVALID_REQUEST;
      res.message = req.role > cellsight::CyclePass::REFINE
                        ? "unknown pass role " + std::to_string(req.role) + " (cellsight/CyclePass: 0 detect, 1 add_detections, 2 refine)"
                        : "a later pass (role " + std::to_string(req.role) + ") needs the cycle_id of its detect pass";
      return true;
    }
    const std::string name_problem = cellsight_ros::outputNameProblem(req.output_file, {".ply", ".pcd"});
    if (!name_problem.empty()) {
      res.status = cellsight::FinishScan::Response::INVALID_REQUEST;
      res.message = "output_file: " + name_problem + " (it is written into ~output_dir, " + output_dir_ + ")";
      return true;
    }
    cellsight::ScanCloud cloud;
    Eigen::Vector3f viewpoint;
    ros::Time stamp;
    std::vector<std::pair<ros::Time, Eigen::Isometry3d>> sweep;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      if (req.expected_frames > 0) {
        const double wait = req.wait_frames_timeout > 0 ? req.wait_frames_timeout : 10.0;
        if (!cv_.wait_for(lock, std::chrono::duration<double>(wait),
                          [&] { return frames_ >= req.expected_frames; })) {
          res.status = cellsight::FinishScan::Response::TIMEOUT;
          res.message = "only " + std::to_string(frames_) + " of " + std::to_string(req.expected_frames) +
                        " frames arrived with a laser plane within " + std::to_string(wait) +
                        " s (is laser_plane_tracker running, and tf complete?)";
          res.frames = frames_;
          return true;
        }
      }
      cloud = joinedProfiles();
      sweep = sweep_;
      viewpoint = camera_center_;
      stamp = last_stamp_;
      res.frames = frames_;
    }
    cloud.frame_id = base_frame_;
    cloud = cellsight::finishScan(cloud, settings_, viewpoint);
    if (cloud.size() == 0) {
      res.status = cellsight::FinishScan::Response::EMPTY;
      res.message = "the scan is empty: no laser line was found in any frame";
      return true;
    }
    // the scan is as old as its last frame: consumers look transforms up at that stamp
    res.cloud = cellsight_ros::toCloudMsg(cloud, stamp);
    res.points = static_cast<uint32_t>(cloud.size());
    // the sheet frame by frame in time order, with the cloud's stamp; sent first, so that it is
    // there when the clusters of this cloud reach the matcher
    std::sort(sweep.begin(), sweep.end(), [](const auto& a, const auto& b) { return a.first < b.first; });
    cellsight::LightSweep light;
    light.setFanHalfAngle(settings_.laser_fan_angle / 2);
    for (const auto& f : sweep) light.addLaserFrame(f.second);
    cellsight::CyclePass pass;
    pass.header = res.cloud.header;
    pass.cycle_id = req.cycle_id;
    pass.role = req.role;
    pass.last = req.last_pass;
    pass.frames = res.frames;
    pass_pub_.publish(pass);
    sweep_pub_.publish(cellsight_ros::toLaserSweepMsg(light, base_frame_, stamp));
    cloud_pub_.publish(res.cloud);
    if (!req.output_file.empty()) {
      try {
        res.output_path = output_dir_ + "/" + req.output_file;
        cellsight::makeDirs(output_dir_);
        cellsight::saveCloud(res.output_path, cloud);
      } catch (const std::exception& e) {
        res.status = cellsight::FinishScan::Response::SAVE_FAILED;
        res.message = e.what();
        return true;
      }
    }
    res.status = cellsight::FinishScan::Response::OK;
    res.message = "scan of " + std::to_string(res.points) + " points from " + std::to_string(res.frames) + " frames";
    ROS_INFO("triangulation: %s%s%s", res.message.c_str(), req.output_file.empty() ? "" : ", saved to ",
             res.output_path.c_str());
    return true;
  }

  cellsight_ros::NodeDiagnostics diag_;
  cellsight::ScannerSettings settings_;    // config/scanner.yaml as loaded
  cellsight::LineExtractionConfig line_;  // its line thresholds, changed by reconfigure; guarded by mutex_
  boost::recursive_mutex reconfigure_mutex_;
  std::unique_ptr<dynamic_reconfigure::Server<cellsight::ScannerLineConfig>> reconfigure_;
  std::string base_frame_ = "base_link";
  std::string output_dir_;  // where scan/finish saves clouds
  std::string laser_frame_ = "laser";
  tf2_ros::Buffer buffer_;
  tf2_ros::TransformListener listener_;
  image_transport::ImageTransport it_;
  image_transport::SubscriberFilter image_sub_;
  message_filters::Subscriber<cellsight::LaserPlaneStamped> plane_sub_;
  message_filters::TimeSynchronizer<sensor_msgs::Image, cellsight::LaserPlaneStamped> sync_;
  ros::Subscriber info_sub_;
  ros::Publisher profile_pub_, cloud_pub_, sweep_pub_, pass_pub_;
  ros::ServiceServer reset_srv_, finish_srv_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::shared_ptr<const cellsight::UndistortionMap> map_;
  using Frame = std::pair<sensor_msgs::ImageConstPtr, cellsight::LaserPlaneStampedConstPtr>;
  static constexpr size_t kMaxHeldFrames = 50;
  std::deque<Frame> held_;  // frames that came before the first camera_info
  std::vector<std::pair<ros::Time, cellsight::ScanCloud>> profiles_;  // the scan's frames, base frame
  uint32_t frames_ = 0;
  ros::Time last_stamp_;  // newest frame in profiles_
  std::vector<std::pair<ros::Time, Eigen::Isometry3d>> sweep_;  // T_base_laser of profiles_' frames
  Eigen::Vector3f camera_center_ = Eigen::Vector3f::Zero();
};

}  // namespace

// scan/finish waits for frames that other callbacks process.
CELLSIGHT_NODE(Triangulation, "triangulation", 3)
