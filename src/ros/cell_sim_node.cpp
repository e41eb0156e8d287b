// cell_sim: the built-in simulated robot cell. Publishes what real drivers publish (scanner and
// fixture camera images + camera_info, base_link→flange in tf), simulates the robot's motion and
// the two-signal stop-and-go handshake (docs/interfaces.md), and writes the ground truth.
#include <geometry_msgs/TransformStamped.h>
#include <image_transport/image_transport.h>
#include <ros/ros.h>
#include <std_msgs/Bool.h>
#include <tf2_ros/transform_broadcaster.h>
#include <visualization_msgs/MarkerArray.h>

#include <algorithm>
#include <cmath>
#include <chrono>
#include <condition_variable>
#include <fstream>
#include <memory>
#include <mutex>

#include "cellsight/MoveFlange.h"
#include "cellsight/sim/ground_truth.hpp"
#include "cellsight/sim/robot_model.hpp"
#include "cellsight/sim/renderer.hpp"
#include "cellsight/sim/scene.hpp"
#include "cellsight_ros/conversions.hpp"
#include "cellsight_ros/node.hpp"
#include "cellsight_ros/diagnostics.hpp"
#include "cellsight_ros/params.hpp"

namespace {

using cellsight::MoveFlange;

class CellSim {
 public:
  CellSim(ros::NodeHandle& nh, ros::NodeHandle& pnh) : diag_(nh, pnh, "cell_sim", "scanner frames"), it_(nh) {
    std::string scene_file = cellsight_ros::requireParam<std::string>(
        pnh, "scene", "path of the scene YAML, e.g. $(find cellsight)/config/scenes/demo.yaml");
    cellsight::Scene scene = cellsight::loadScene(scene_file);
    double scanner_rate = -1.0;
    cellsight_ros::param(pnh, "scanner_frame_rate", scanner_rate);
    if (scanner_rate >= 0) scene.scanner_camera.frame_rate = scanner_rate;
    bool noise = scene.noise.enabled;
    cellsight_ros::param(pnh, "noise", noise);
    scene.noise.enabled = noise;
    cellsight_ros::param(pnh, "truth_dir", truth_dir_);
    // Like a camera driver's camera_info_url: the intrinsics the camera publishes with its frames
    // (a calibration the user made); empty: the simulator's truth.
    std::string info_file;
    cellsight_ros::param(pnh, "scanner_camera_info", info_file);
    bool perfect = scene.as_built.perfect;
    cellsight_ros::param(pnh, "perfect", perfect);
    if (perfect && !scene.as_built.perfect) cellsight::makePerfect(scene);
    cellsight_ros::param(pnh, "handshake", handshake_);
    double tf_rate = 100.0;
    cellsight_ros::param(pnh, "tf_rate", tf_rate);
    if (!(tf_rate > 0)) throw std::runtime_error("~tf_rate must be > 0");

    const auto t0 = std::chrono::steady_clock::now();
    geometry_ = std::make_shared<cellsight::CellGeometry>(scene);
    scanner_ = std::make_unique<cellsight::ScannerRenderer>(geometry_);
    fixture_ = std::make_unique<cellsight::FixtureRenderer>(geometry_);
    ROS_INFO("cell_sim: scene '%s' (%zu objects, %zu fixtures) ready in %.2f s",
             scene.name.c_str(), scene.objects.size(), scene.fixtures.size(),
             std::chrono::duration<double>(std::chrono::steady_clock::now() - t0).count());

    const cellsight::Scene& s = geometry_->scene();
    robot_ = cellsight::RobotErrorModel(s.as_built.robot);
    scanner_info_ = s.scanner_camera.intrinsics;
    if (!info_file.empty()) {
      scanner_info_ = cellsight::loadCameraInfoYaml(info_file);
      if (scanner_info_.width != s.scanner_camera.intrinsics.width || scanner_info_.height != s.scanner_camera.intrinsics.height)
        throw std::runtime_error("~scanner_camera_info " + info_file + ": " + std::to_string(scanner_info_.width) + "x" +
                                 std::to_string(scanner_info_.height) + " does not match the camera's " +
                                 std::to_string(s.scanner_camera.intrinsics.width) + "x" +
                                 std::to_string(s.scanner_camera.intrinsics.height));
      ROS_INFO("cell_sim: scanner camera publishes the intrinsics of %s", info_file.c_str());
    }
    if (robot_.enabled())
      ROS_INFO("cell_sim: cell as built: camera and laser mounted off their drawing, robot with kinematic error "
               "(joint offsets %.3f deg, links %.2f mm, repeatability %.3f mm)", s.as_built.robot.joint_offset_deg,
               s.as_built.robot.link_mm, s.as_built.robot.repeatability_mm);
    pose_ = s.robot.home;
    if (!truth_dir_.empty()) {
      cellsight::writeSceneTruth(s, truth_dir_);
      frames_truth_.open(truth_dir_ + "/frames_truth.jsonl", std::ios::app);
      if (!frames_truth_) throw std::runtime_error(truth_dir_ + "/frames_truth.jsonl: cannot open");
      ROS_INFO("cell_sim: ground truth and true calibration written to %s", truth_dir_.c_str());
    } else {
      ROS_WARN("cell_sim: ~truth_dir is empty: no ground truth is written");
    }

    scanner_pub_ = it_.advertiseCamera("scanner_camera/image_raw", 2);
    fixture_pub_ = it_.advertiseCamera("fixture_camera/image_raw", 2);
    in_position_pub_ = nh.advertise<std_msgs::Bool>("io/in_position", 1, true);
    plane_pub_ = nh.advertise<cellsight::LaserPlaneStamped>("truth/laser_plane", 10);
    markers_pub_ = nh.advertise<visualization_msgs::MarkerArray>("sim/scene_markers", 1, true);
    capture_done_sub_ = nh.subscribe("io/capture_done", 10, &CellSim::onCaptureDone, this);
    move_srv_ = nh.advertiseService("robot/move_flange", &CellSim::onMove, this);
    publishMarkers();
    setInPosition(true);

    tf_timer_ = nh.createTimer(ros::Duration(1.0 / tf_rate), &CellSim::onTick, this);
    if (s.fixture_camera.frame_rate > 0) {
      fixture_timer_ = nh.createTimer(ros::Duration(1.0 / s.fixture_camera.frame_rate),
                                      &CellSim::onFixtureFrame, this);
    }
    if (s.scanner_camera.frame_rate > 0) {
      scanner_timer_ = nh.createTimer(ros::Duration(1.0 / s.scanner_camera.frame_rate),
                                      [this](const ros::TimerEvent&) { capture(ros::Time::now()); });
    }
  }

 private:
  bool onMove(MoveFlange::Request& req, MoveFlange::Response& res) {
    std::unique_lock<std::mutex> lock(mutex_);
    const cellsight::Scene& s = geometry_->scene();
    if (!req.target.header.frame_id.empty() && req.target.header.frame_id != s.base_frame) {
      res.status = MoveFlange::Response::REJECTED_INVALID;
      res.message = "target frame '" + req.target.header.frame_id + "' is not the robot base '" +
                    s.base_frame + "'";
      return true;
    }
    if (!std::isfinite(req.speed_scale) || req.speed_scale < 0 || req.speed_scale > 1) {
      res.status = MoveFlange::Response::REJECTED_INVALID;
      res.message = "speed_scale must lie in [0, 1] (0: full speed), got " + std::to_string(req.speed_scale);
      return true;
    }
    Eigen::Isometry3d target;
    try {
      target = cellsight_ros::fromPoseMsg(req.target.pose);
    } catch (const std::exception& e) {
      res.status = MoveFlange::Response::REJECTED_INVALID;
      res.message = e.what();
      return true;
    }
    if (moving_) {
      res.status = MoveFlange::Response::REJECTED_BUSY;
      res.message = "robot is still moving";
      return true;
    }
    // Like a robot program's WAIT on its "capture done" input: the acknowledgement travels on a
    // topic and may arrive just after this request, so wait a moment before refusing.
    if (handshake_ && awaiting_capture_) {
      capture_cv_.wait_for(lock, std::chrono::milliseconds(500), [&] { return !awaiting_capture_; });
    }
    if (handshake_ && awaiting_capture_) {
      res.status = MoveFlange::Response::REJECTED_BUSY;
      res.message = "robot waits for io/capture_done after the last in-position signal";
      return true;
    }
    if (!s.robot.reach.contains(target.translation())) {
      res.status = MoveFlange::Response::REJECTED_UNREACHABLE;
      res.message = "target outside the robot's reach box";
      return true;
    }
    const double scale = req.speed_scale > 0 && req.speed_scale <= 1 ? req.speed_scale : 1.0;
    const double dist = (target.translation() - pose_.translation()).norm();
    const double angle = Eigen::AngleAxisd(pose_.linear().transpose() * target.linear()).angle();
    duration_ = std::max(dist / s.robot.linear_speed, angle / s.robot.angular_speed) / scale;
    start_pose_ = pose_;
    target_pose_ = target;
    move_start_ = ros::Time::now();
    moving_ = true;
    setInPosition(false);
    res.status = MoveFlange::Response::OK;
    res.message = "moving";
    res.expected_duration = duration_ + s.robot.settle_time;
    return true;
  }

  void onCaptureDone(const std_msgs::Bool::ConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (msg->data) awaiting_capture_ = false;
    capture_cv_.notify_all();
  }

  /// The flange pose at time t of the current motion (mutex_ held).
  Eigen::Isometry3d poseAt(const ros::Time& t) const {
    if (!moving_) return pose_;
    const double a = duration_ > 0 ? std::clamp((t - move_start_).toSec() / duration_, 0.0, 1.0) : 1.0;
    const Eigen::Quaterniond q0(start_pose_.linear()), q1(target_pose_.linear());
    Eigen::Isometry3d p = Eigen::Isometry3d::Identity();
    p.linear() = q0.slerp(a, q1).toRotationMatrix();
    p.translation() = (1 - a) * start_pose_.translation() + a * target_pose_.translation();
    return p;
  }

  void onTick(const ros::TimerEvent&) {
    std::unique_lock<std::mutex> lock(mutex_);
    const ros::Time now = ros::Time::now();
    bool arrived = false;
    if (moving_) {
      pose_ = poseAt(now);
      if ((now - move_start_).toSec() >= duration_ + geometry_->scene().robot.settle_time) {
        pose_ = target_pose_;
        moving_ = false;
        arrived = true;
      }
    }
    publishFlange(now, pose_);
    if (arrived) {
      awaiting_capture_ = true;
      setInPosition(true);
      // The in-position output is wired to the scanner camera's trigger input.
      if (geometry_->scene().scanner_camera.frame_rate <= 0) {
        lock.unlock();
        capture(now);
      }
    }
  }

  void publishFlange(const ros::Time& stamp, const Eigen::Isometry3d& pose) {
    if (stamp == last_tf_stamp_) return;  // tf2 rejects a repeated stamp
    last_tf_stamp_ = stamp;
    const cellsight::Scene& s = geometry_->scene();
    geometry_msgs::TransformStamped ts;
    ts.header.stamp = stamp;
    ts.header.frame_id = s.base_frame;
    ts.child_frame_id = s.flange_frame;
    ts.transform = cellsight_ros::toTransformMsg(pose);
    tf_.sendTransform(ts);
  }

  void capture(const ros::Time& stamp) {
    std::lock_guard<std::mutex> capture_lock(capture_mutex_);
    Eigen::Isometry3d pose;
    {
      // The pose at the exposure stamp, also sent to tf with that stamp (continuous scans).
      std::lock_guard<std::mutex> lock(mutex_);
      pose = poseAt(stamp);
      publishFlange(stamp, pose);
    }
    const cellsight::Scene& s = geometry_->scene();
    const auto t0 = std::chrono::steady_clock::now();
    // The controller reports `pose` (tf above); the flange really is at `actual`.
    Eigen::Isometry3d actual;
    try {
      actual = robot_.actual(pose, s.noise.seed * 1000003ull + frame_count_);
    } catch (const std::exception& e) {
      ROS_ERROR("cell_sim: %s: frame not captured", e.what());
      return;
    }
    const cv::Mat image = scanner_->render(actual, s.noise.seed * 1000003ull + frame_count_);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    const cellsight::Plane plane = scanner_->planeInCamera(actual);
    auto img = boost::make_shared<sensor_msgs::Image>(
        cellsight_ros::toImageMsg(image, s.scanner_camera.frame_id, stamp));
    auto info = boost::make_shared<sensor_msgs::CameraInfo>(
        cellsight_ros::toCameraInfo(scanner_info_, s.scanner_camera.frame_id, stamp));
    scanner_pub_.publish(img, info);
    diag_.processed(ms * 1e-3);
    plane_pub_.publish(cellsight_ros::toPlaneMsg(plane, s.scanner_camera.frame_id, stamp));
    if (frames_truth_.is_open()) {
      frames_truth_ << cellsight::frameTruthJsonLine(frame_count_, cellsight_ros::toNanoseconds(stamp),
                                                     actual, plane);
      frames_truth_.flush();
    }
    ROS_DEBUG("cell_sim: scanner frame %d rendered in %.1f ms", frame_count_, ms);
    ++frame_count_;
  }

  void onFixtureFrame(const ros::TimerEvent&) {
    if (fixture_pub_.getNumSubscribers() == 0) return;
    const cellsight::Scene& s = geometry_->scene();
    const ros::Time stamp = ros::Time::now();
    const cv::Mat image = fixture_->render(s.noise.seed * 7919ull + fixture_count_++);
    auto img = boost::make_shared<sensor_msgs::Image>(
        cellsight_ros::toImageMsg(image, s.fixture_camera.frame_id, stamp));
    auto info = boost::make_shared<sensor_msgs::CameraInfo>(
        cellsight_ros::toCameraInfo(s.fixture_camera.intrinsics, s.fixture_camera.frame_id, stamp));
    fixture_pub_.publish(img, info);
  }

  void setInPosition(bool value) {
    std_msgs::Bool b;
    b.data = value;
    in_position_pub_.publish(b);
  }

  void publishMarkers() {
    const cellsight::Scene& s = geometry_->scene();
    visualization_msgs::MarkerArray arr;
    int id = 0;
    auto base = [&](const std::string& ns) {
      visualization_msgs::Marker m;
      m.header.frame_id = s.base_frame;
      m.ns = ns;
      m.id = id++;
      m.action = visualization_msgs::Marker::ADD;
      m.pose.orientation.w = 1;
      m.scale.x = m.scale.y = m.scale.z = 1;
      m.color.a = 1;
      return m;
    };
    visualization_msgs::Marker table = base("table");
    table.type = visualization_msgs::Marker::CUBE;
    table.pose.position.x = s.table.center.x();
    table.pose.position.y = s.table.center.y();
    table.pose.position.z = s.table.z - 0.01;
    table.scale.x = s.table.size.x();
    table.scale.y = s.table.size.y();
    table.scale.z = 0.02;
    table.color.r = table.color.g = table.color.b = 0.45f;
    arr.markers.push_back(table);
    for (const auto& o : s.objects) {
      visualization_msgs::Marker m = base("objects");
      m.type = visualization_msgs::Marker::TRIANGLE_LIST;
      m.pose = cellsight_ros::toPoseMsg(o.T_base_object);
      const cellsight::TriangleMesh mesh = cellsight::loadValidMesh(o.info.mesh_file);
      for (const auto& f : mesh.faces) {
        for (int k = 0; k < 3; ++k) {
          geometry_msgs::Point p;
          p.x = mesh.vertices[f[k]].x();
          p.y = mesh.vertices[f[k]].y();
          p.z = mesh.vertices[f[k]].z();
          m.points.push_back(p);
        }
      }
      m.color.r = 0.2f + 0.6f * static_cast<float>(o.reflectivity);
      m.color.g = 0.55f;
      m.color.b = 0.75f;
      arr.markers.push_back(m);
    }
    for (const auto& f : s.fixtures) {
      visualization_msgs::Marker m = base("fixtures");
      m.type = visualization_msgs::Marker::CUBE;
      m.pose = cellsight_ros::toPoseMsg(f.T_base_fixture);
      m.scale.x = m.scale.y = f.plate_size;
      m.scale.z = 0.003;
      m.color.r = m.color.g = m.color.b = 0.95f;
      arr.markers.push_back(m);
    }
    // The light sheet as a translucent fan in the laser frame: rviz carries it with the flange.
    visualization_msgs::Marker fan = base("laser_sheet");
    fan.header.frame_id = s.laser_frame;
    fan.type = visualization_msgs::Marker::TRIANGLE_LIST;
    const double reach = 0.45, half = s.laser.fan_angle / 2;
    const int n = 24;
    for (int i = 0; i < n; ++i) {
      const double a0 = -half + 2 * half * i / n, a1 = -half + 2 * half * (i + 1) / n;
      geometry_msgs::Point o, p0, p1;
      p0.x = reach * std::sin(a0);
      p0.z = reach * std::cos(a0);
      p1.x = reach * std::sin(a1);
      p1.z = reach * std::cos(a1);
      fan.points.insert(fan.points.end(), {o, p0, p1});
    }
    fan.color.r = 1.0f;
    fan.color.g = 0.1f;
    fan.color.b = 0.1f;
    fan.color.a = 0.25f;
    arr.markers.push_back(fan);
    markers_pub_.publish(arr);
  }

  cellsight_ros::NodeDiagnostics diag_;
  image_transport::ImageTransport it_;
  std::shared_ptr<const cellsight::CellGeometry> geometry_;
  std::unique_ptr<cellsight::ScannerRenderer> scanner_;
  std::unique_ptr<cellsight::FixtureRenderer> fixture_;
  std::string truth_dir_;
  cellsight::RobotErrorModel robot_;
  cellsight::CameraIntrinsics scanner_info_;
  bool handshake_ = true;
  std::ofstream frames_truth_;
  tf2_ros::TransformBroadcaster tf_;
  image_transport::CameraPublisher scanner_pub_, fixture_pub_;
  ros::Publisher in_position_pub_, plane_pub_, markers_pub_;
  ros::Subscriber capture_done_sub_;
  ros::ServiceServer move_srv_;
  ros::Timer tf_timer_, fixture_timer_, scanner_timer_;
  std::mutex mutex_, capture_mutex_;
  std::condition_variable capture_cv_;
  Eigen::Isometry3d pose_, start_pose_, target_pose_;
  ros::Time move_start_, last_tf_stamp_;
  double duration_ = 0;
  bool moving_ = false;
  bool awaiting_capture_ = false;
  int frame_count_ = 0;
  uint64_t fixture_count_ = 0;
};

}  // namespace

// Rendering must not stall the flange tf or the I/O.
CELLSIGHT_NODE(CellSim, "cell_sim", 3)
