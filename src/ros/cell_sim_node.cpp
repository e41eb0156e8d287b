// cell_sim: the built-in simulated robot cell. Publishes what real drivers publish (scanner and
// fixture camera images + camera_info, base_link→flange in tf, joint_states of the arm when
// /robot_description holds its URDF), simulates the robot's motion and the two-signal stop-and-go
// handshake (docs/interfaces.md), executes grasp plans (robot/execute_plan: the part between the
// jaws rides with the gripper as built, and the cell is rendered with it where it was put down),
// and writes the ground truth.
#include <geometry_msgs/TransformStamped.h>
#include <image_transport/image_transport.h>
#include <sensor_msgs/JointState.h>
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

#include "cellsight/ExecutePlan.h"
#include "cellsight/MoveFlange.h"
#include "cellsight/common/raycaster.hpp"
#include "cellsight/planning/arm_model.hpp"
#include "cellsight/sim/ground_truth.hpp"
#include "cellsight/sim/robot_model.hpp"
#include "cellsight/sim/renderer.hpp"
#include "cellsight/sim/scene.hpp"
#include "cellsight_ros/conversions.hpp"
#include "cell_markers.hpp"
#include "cellsight_ros/node.hpp"
#include "cellsight_ros/diagnostics.hpp"
#include "cellsight_ros/params.hpp"

namespace {

using cellsight::ExecutePlan;
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
    scanner_ = std::make_shared<cellsight::ScannerRenderer>(geometry_);
    fixture_ = std::make_shared<cellsight::FixtureRenderer>(geometry_);
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
    // the arm's joints (for robot_state_publisher and grasp plans) when its URDF is loaded
    std::string urdf;
    if (nh.getParam("robot_description", urdf) && !urdf.empty()) {
      arm_ = std::make_unique<cellsight::ArmModel>(cellsight::ArmModel::fromUrdfString(urdf, nh.resolveName("robot_description")));
      const auto q = arm_->ik(pose_, (cellsight::JointVector() << 0.0, 0.5, 0.64, 0.0, 0.43, 0.0).finished());
      if (!q) throw std::runtime_error("the robot's home pose has no inverse kinematics within the URDF's joint limits");
      q_ = *q;
      joints_pub_ = nh.advertise<sensor_msgs::JointState>("joint_states", 10);
      execute_srv_ = nh.advertiseService("robot/execute_plan", &CellSim::onExecute, this);
    } else {
      ROS_INFO("cell_sim: no %s: no joint_states, no robot/execute_plan", nh.resolveName("robot_description").c_str());
    }
    if (!truth_dir_.empty()) {
      cellsight::writeSceneTruth(s, truth_dir_);
      frames_truth_.open(truth_dir_ + "/frames_truth.jsonl", std::ios::app);
      if (!frames_truth_) throw std::runtime_error(truth_dir_ + "/frames_truth.jsonl: cannot open");
      placements_truth_.open(truth_dir_ + "/placements.jsonl", std::ios::app);
      if (!placements_truth_) throw std::runtime_error(truth_dir_ + "/placements.jsonl: cannot open");
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
    if (moving_ || executing_) {
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
    if (executing_) {
      lock.unlock();
      stepExecution(now);
      lock.lock();
    }
    publishFlange(now, pose_);
    publishJoints(now);
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

  bool onExecute(ExecutePlan::Request& req, ExecutePlan::Response& res) {
    using R = ExecutePlan::Response;
    std::lock_guard<std::mutex> lock(mutex_);
    cellsight::TimedTrajectory traj;
    try {
      traj = cellsight_ros::fromTrajectoryMsg(req.plan.trajectory, arm_->jointNames());
    } catch (const std::exception& e) {
      res.status = R::REJECTED_INVALID;
      res.message = e.what();
      return true;
    }
    const size_t n = traj.positions.size();
    if (req.plan.grasp_index >= n || req.plan.release_index >= n || req.plan.grasp_index > req.plan.release_index) {
      res.status = R::REJECTED_INVALID;
      res.message = "grasp_index and release_index must lie in the trajectory, the grasp first";
      return true;
    }
    if (!std::isfinite(req.time_scale) || req.time_scale < 0 || req.time_scale > 10) {
      res.status = R::REJECTED_INVALID;
      res.message = "time_scale must lie in [0, 10] (0: as planned)";
      return true;
    }
    for (const auto& q : traj.positions) {
      if (!arm_->withinLimits(q)) {
        res.status = R::REJECTED_INVALID;
        res.message = "a trajectory point lies outside the joint limits";
        return true;
      }
    }
    if (moving_ || executing_ || (handshake_ && awaiting_capture_)) {
      res.status = R::REJECTED_BUSY;
      res.message = moving_ || executing_ ? "robot is still moving" : "robot waits for io/capture_done";
      return true;
    }
    if (cellsight::jointDistance(traj.positions.front(), q_) > 0.01) {
      res.status = R::REJECTED_START;
      res.message = "the trajectory starts " + std::to_string(cellsight::jointDistance(traj.positions.front(), q_)) +
                    " rad from the robot's joints";
      return true;
    }
    traj_ = traj;
    grasp_index_ = req.plan.grasp_index;
    release_index_ = req.plan.release_index;
    time_scale_ = req.time_scale > 0 ? req.time_scale : 1.0;
    exec_start_ = ros::Time::now();
    exec_object_ = req.plan.object;
    next_event_ = 0;
    executing_ = true;
    setInPosition(false);
    res.status = R::OK;
    res.expected_duration = traj.duration() / time_scale_;
    res.message = "executing " + std::to_string(n) + " points";
    return true;
  }

  /// The trajectory at `now`: joints, the reported flange, the jaws' events (mutex_ not held).
  void stepExecution(const ros::Time& now) {
    std::unique_lock<std::mutex> lock(mutex_);
    const double t = (now - exec_start_).toSec() * time_scale_;
    const auto& times = traj_.times;
    size_t i = std::upper_bound(times.begin(), times.end(), t) - times.begin();
    cellsight::JointVector q;
    if (i >= times.size()) {
      q = traj_.positions.back();
      i = times.size();
    } else if (i == 0) {
      q = traj_.positions.front();
    } else {
      const double a = (t - times[i - 1]) / std::max(1e-9, times[i] - times[i - 1]);
      q = traj_.positions[i - 1] + a * (traj_.positions[i] - traj_.positions[i - 1]);
    }
    q_ = q;
    pose_ = arm_->fk(q);
    // the jaws close at the grasp point and open at the release point, once each and in this
    // order, even when one tick passes both (or the end)
    const bool done = i >= times.size();
    const bool grasp = next_event_ == 0 && (i > grasp_index_ || done);
    if (grasp) next_event_ = 1;
    const bool release = next_event_ == 1 && (i > release_index_ || done);
    if (release) next_event_ = 2;
    const std::string object = exec_object_;
    if (done) {
      executing_ = false;
      q_ = traj_.positions.back();
      pose_ = arm_->fk(q_);
    }
    const cellsight::JointVector q_grasp = traj_.positions[grasp_index_], q_release = traj_.positions[release_index_];
    lock.unlock();
    try {
      if (grasp) closeJaws(q_grasp);
      if (release) openJaws(q_release, now, object);
    } catch (const std::exception& e) {
      ROS_ERROR("cell_sim: the jaws of '%s': %s (the part stays where it was)", object.c_str(), e.what());
      held_ = -1;
    }
    if (done) {
      setInPosition(true);
      ROS_INFO("cell_sim: trajectory of '%s' executed", object.c_str());
    }
  }

  /// Where the tcp really is when the controller is at `q` (the arm as built), move number `move`.
  Eigen::Isometry3d actualTcp(const cellsight::JointVector& q, uint64_t move) const {
    return robot_.actualAtJoints(q, move) * arm_->toolTcp();
  }

  void closeJaws(const cellsight::JointVector& q) {
    const cellsight::Scene& s = geometry_->scene();
    const Eigen::Isometry3d tcp = actualTcp(q, 7000000ull + moves_++);
    held_ = -1;
    double best = 1e9;
    for (size_t k = 0; k < s.objects.size(); ++k) {
      // the tcp inside the part's bounding box (5 mm margin): the part is between the jaws
      const cellsight::TriangleMesh& mesh = meshOf(s.objects[k]);
      const Eigen::Vector3f p = (s.objects[k].T_base_object.inverse() * tcp.translation()).cast<float>();
      Eigen::AlignedBox3f box = mesh.bounds();
      box.min().array() -= 0.005f;
      box.max().array() += 0.005f;
      if (!box.contains(p)) continue;
      const double d = (p - box.center()).norm();
      if (d < best) {
        best = d;
        held_ = static_cast<int>(k);
      }
    }
    if (held_ < 0) {
      ROS_WARN("cell_sim: the jaws closed on nothing (no part at %.3f %.3f %.3f)", tcp.translation().x(), tcp.translation().y(),
               tcp.translation().z());
      return;
    }
    T_tcp_held_ = tcp.inverse() * s.objects[static_cast<size_t>(held_)].T_base_object;
    ROS_INFO("cell_sim: the jaws closed on '%s'", s.objects[static_cast<size_t>(held_)].name.c_str());
  }

  void openJaws(const cellsight::JointVector& q, const ros::Time& stamp, const std::string& plan_object) {
    if (held_ < 0) return;
    const Eigen::Isometry3d tcp = actualTcp(q, 7000000ull + moves_++);
    cellsight::Scene scene = geometry_->scene();
    cellsight::SceneObject& o = scene.objects[static_cast<size_t>(held_)];
    o.T_base_object = tcp * T_tcp_held_;
    held_ = -1;
    // the cell with the part where it was put down: later frames and markers show it there
    auto geometry = std::make_shared<cellsight::CellGeometry>(scene);
    auto scanner = std::make_shared<cellsight::ScannerRenderer>(geometry);
    auto fixture = std::make_shared<cellsight::FixtureRenderer>(geometry);
    {
      std::lock_guard<std::mutex> lock(mutex_);
      std::lock_guard<std::mutex> render_lock(render_mutex_);
      geometry_ = geometry;
      scanner_ = scanner;
      fixture_ = fixture;
    }
    if (placements_truth_.is_open()) {
      const Eigen::Vector3d t = o.T_base_object.translation();
      const Eigen::Quaterniond r(o.T_base_object.linear());
      char line[512];
      std::snprintf(line, sizeof line,
                    "{\"object\": \"%s\", \"model\": \"%s\", \"plan_object\": \"%s\", \"stamp_ns\": %lld, "
                    "\"pose\": {\"xyz\": [%.9f, %.9f, %.9f], \"quat\": [%.12f, %.12f, %.12f, %.12f]}}\n",
                    o.name.c_str(), o.model.c_str(), plan_object.c_str(), static_cast<long long>(cellsight_ros::toNanoseconds(stamp)),
                    t.x(), t.y(), t.z(), r.x(), r.y(), r.z(), r.w());
      placements_truth_ << line;
      placements_truth_.flush();
    }
    ROS_INFO("cell_sim: '%s' put down at %.4f %.4f %.4f", o.name.c_str(), o.T_base_object.translation().x(),
             o.T_base_object.translation().y(), o.T_base_object.translation().z());
    publishMarkers();
  }

  const cellsight::TriangleMesh& meshOf(const cellsight::SceneObject& o) {
    auto it = meshes_.find(o.info.mesh_file);
    if (it == meshes_.end()) it = meshes_.emplace(o.info.mesh_file, cellsight::loadValidMesh(o.info.mesh_file)).first;
    return it->second;
  }

  void publishJoints(const ros::Time& stamp) {
    if (!arm_) return;
    if (!executing_) {
      // the joints of the reported flange pose (the branch of the last joints)
      const auto q = arm_->ik(pose_, q_);
      if (q) q_ = *q;
    }
    sensor_msgs::JointState js;
    js.header.stamp = stamp;
    for (int j = 0; j < 6; ++j) {
      js.name.push_back(arm_->jointNames()[static_cast<size_t>(j)]);
      js.position.push_back(q_[j]);
    }
    // the jaws: open, or closed on the part
    js.name.push_back("finger_right_joint");
    js.position.push_back(held_ >= 0 ? 0.01 : 0.035);
    js.name.push_back("finger_left_joint");
    js.position.push_back(held_ >= 0 ? 0.01 : 0.035);
    joints_pub_.publish(js);
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
    std::shared_ptr<const cellsight::ScannerRenderer> scanner;
    {
      std::lock_guard<std::mutex> lock(render_mutex_);
      scanner = scanner_;
    }
    const cellsight::Scene& s = scanner->geometry().scene();
    const auto t0 = std::chrono::steady_clock::now();
    // The controller reports `pose` (tf above); the flange really is at `actual`.
    Eigen::Isometry3d actual;
    try {
      actual = robot_.actual(pose, s.noise.seed * 1000003ull + frame_count_);
    } catch (const std::exception& e) {
      ROS_ERROR("cell_sim: %s: frame not captured", e.what());
      return;
    }
    const cv::Mat image = scanner->render(actual, s.noise.seed * 1000003ull + frame_count_);
    const double ms = std::chrono::duration<double, std::milli>(std::chrono::steady_clock::now() - t0).count();
    const cellsight::Plane plane = scanner->planeInCamera(actual);
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
    std::shared_ptr<const cellsight::FixtureRenderer> fixture;
    {
      std::lock_guard<std::mutex> lock(render_mutex_);
      fixture = fixture_;
    }
    const cellsight::Scene& s = fixture->geometry().scene();
    const ros::Time stamp = ros::Time::now();
    const cv::Mat image = fixture->render(s.noise.seed * 7919ull + fixture_count_++);
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
    std::shared_ptr<const cellsight::CellGeometry> geometry;
    {
      std::lock_guard<std::mutex> lock(render_mutex_);
      geometry = geometry_;
    }
    markers_pub_.publish(cellsight_ros::cellMarkers(geometry->scene()));
  }

  cellsight_ros::NodeDiagnostics diag_;
  image_transport::ImageTransport it_;
  std::shared_ptr<const cellsight::CellGeometry> geometry_;
  std::shared_ptr<const cellsight::ScannerRenderer> scanner_;
  std::shared_ptr<const cellsight::FixtureRenderer> fixture_;
  std::mutex render_mutex_;  // guards the three pointers above (swapped when a part is put down)
  std::unique_ptr<cellsight::ArmModel> arm_;
  cellsight::JointVector q_ = cellsight::JointVector::Zero();
  cellsight::TimedTrajectory traj_;
  size_t grasp_index_ = 0, release_index_ = 0;
  int next_event_ = 0;
  double time_scale_ = 1.0;
  ros::Time exec_start_;
  std::string exec_object_;
  bool executing_ = false;
  int held_ = -1;  // scene object between the jaws
  Eigen::Isometry3d T_tcp_held_ = Eigen::Isometry3d::Identity();
  uint64_t moves_ = 0;
  std::map<std::string, cellsight::TriangleMesh> meshes_;
  std::ofstream placements_truth_;
  ros::Publisher joints_pub_;
  ros::ServiceServer execute_srv_;
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
