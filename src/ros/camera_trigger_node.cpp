// camera_trigger: the Scan action. Stop-and-go (thesis §1, two digital signals): for each pose
// command the flange (robot/move_flange), wait for the robot's "in position" output
// (io/in_position), take the camera frame it triggered, pair it with the flange pose from tf at
// the image stamp, acknowledge on io/capture_done so the robot may move on. Continuous mode
// (not in the thesis): the robot moves through the poses while the camera free-runs; every
// frame's flange pose is interpolated by tf at its stamp. At the end the triangulation node
// finishes the cloud (scan/finish). Frames may also be saved as PNG with frames.json.
#include <actionlib/server/simple_action_server.h>
#include <image_transport/image_transport.h>
#include <ros/ros.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/image_encodings.h>
#include <std_msgs/Bool.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <condition_variable>
#include <cmath>
#include <mutex>
#include <nlohmann/json.hpp>
#include <thread>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "cellsight/FinishScan.h"
#include "cellsight/CyclePass.h"
#include "cellsight/MoveFlange.h"
#include "cellsight/ScanAction.h"
#include "cellsight/common/file_io.hpp"
#include "cellsight/common/trajectory.hpp"
#include "cellsight_ros/conversions.hpp"
#include "cellsight_ros/node.hpp"
#include "cellsight_ros/diagnostics.hpp"
#include "cellsight_ros/params.hpp"

namespace {

using cellsight::ScanResult;
using Poses = std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>>;

class CameraTrigger {
 public:
  ~CameraTrigger() {
    if (worker_.joinable()) worker_.join();
  }
  CameraTrigger(ros::NodeHandle& nh, ros::NodeHandle& pnh)
      : nh_(nh), diag_(nh, pnh, "camera_trigger", "frames"), tf_listener_(tf_buffer_), server_(nh, "scan", false) {
    trajectory_file_ = cellsight_ros::requireParam<std::string>(
        pnh, "trajectory_file", "YAML of named trajectories, e.g. config/trajectories.yaml");
    trajectories_ = cellsight::loadTrajectories(trajectory_file_);  // validated at start-up
    cellsight_ros::param(pnh, "base_frame", base_frame_);
    cellsight_ros::param(pnh, "flange_frame", flange_frame_);
    cellsight_ros::param(pnh, "save_dir", save_dir_);
    cellsight_ros::param(pnh, "in_position_timeout", in_position_timeout_);
    cellsight_ros::param(pnh, "capture_timeout", capture_timeout_);
    cellsight_ros::param(pnh, "tf_timeout", tf_timeout_);
    cellsight_ros::param(pnh, "processing_timeout", processing_timeout_);
    move_client_ = nh.serviceClient<cellsight::MoveFlange>("robot/move_flange", true);
    reset_client_ = nh.serviceClient<std_srvs::Trigger>("scan/reset");
    finish_client_ = nh.serviceClient<cellsight::FinishScan>("scan/finish");
    capture_done_pub_ = nh.advertise<std_msgs::Bool>("io/capture_done", 10, true);
    in_position_sub_ = nh.subscribe("io/in_position", 10, &CameraTrigger::onInPosition, this);
    image_sub_ = image_transport::ImageTransport(nh).subscribe("scanner_camera/image_raw", 5, &CameraTrigger::onImage, this);
    server_.registerGoalCallback([this] { onGoal(); });
    server_.start();
    ROS_INFO("camera_trigger: Scan action ready on %s (%zu named trajectories)",
             nh.resolveName("scan").c_str(), trajectories_.size());
  }

 private:
  /// Scans run on a thread of their own, never on a callback thread: as a nodelet the scan's
  /// blocking calls (robot/move_flange, scan/finish) and waits (frames, in-position) need
  /// callbacks of nodelets in the same manager, and the manager may queue one of those behind
  /// the very thread that waits (seen: scan/finish answered only when its 60 s deadline had
  /// passed). A goal that arrives during a scan preempts it and is taken up when it has ended.
  void onGoal() {
    std::lock_guard<std::mutex> lock(goal_mutex_);
    if (busy_) return;  // the running scan sees the preempt request, then takes the new goal
    busy_ = true;
    if (worker_.joinable()) worker_.join();  // a thread that has already ended
    worker_ = std::thread([this] {
      for (;;) {
        runGoal(*server_.acceptNewGoal());
        std::lock_guard<std::mutex> l(goal_mutex_);
        if (!server_.isNewGoalAvailable() || !ros::ok()) {
          busy_ = false;
          return;
        }
      }
    });
  }

  void runGoal(const cellsight::ScanGoal& goal_msg) {
    const cellsight::ScanGoal* goal = &goal_msg;
    ScanResult result;
    try {
      execute(*goal, result);
    } catch (const std::exception& e) {
      result.status = ScanResult::PROCESSING_FAILED;
      result.message = e.what();
    }
    diag_.set("last scan", result.message);
    if (result.status == ScanResult::OK) {
      ROS_INFO("camera_trigger: %s", result.message.c_str());
      server_.setSucceeded(result, result.message);
    } else {
      ROS_ERROR("camera_trigger: scan aborted: %s", result.message.c_str());
      server_.setAborted(result, result.message);
    }
  }

  bool resolvePoses(const cellsight::ScanGoal& goal, Poses& poses, std::string& name, std::string& err) {
    if (!goal.trajectory.empty()) {
      auto it = trajectories_.find(goal.trajectory);
      if (it == trajectories_.end()) {
        err = "no trajectory '" + goal.trajectory + "' in " + trajectory_file_;
        return false;
      }
      poses = it->second.poses;
      name = goal.trajectory;
      return true;
    }
    if (goal.poses.poses.empty()) {
      err = "goal names no trajectory and lists no poses";
      return false;
    }
    if (!goal.poses.header.frame_id.empty() && goal.poses.header.frame_id != base_frame_) {
      err = "poses must be in '" + base_frame_ + "', not '" + goal.poses.header.frame_id + "'";
      return false;
    }
    for (const auto& p : goal.poses.poses) {
      try {
        poses.push_back(cellsight_ros::fromPoseMsg(p));
      } catch (const std::exception& e) {
        err = std::string("invalid pose in goal: ") + e.what();
        return false;
      }
    }
    name = "goal poses";
    return true;
  }

  void execute(const cellsight::ScanGoal& goal, ScanResult& result) {
    Poses poses;
    std::string name, err;
    if (!resolvePoses(goal, poses, name, err)) {
      result.status = ScanResult::INVALID_GOAL;
      result.message = err;
      return;
    }
    if (goal.role > cellsight::CyclePass::REFINE || (goal.role != cellsight::CyclePass::DETECT && goal.cycle_id.empty())) {
      result.status = ScanResult::INVALID_GOAL;
      result.message = goal.role > cellsight::CyclePass::REFINE
                           ? "unknown role " + std::to_string(goal.role) + " (cellsight/CyclePass: 0 detect, 1 add_detections, 2 refine)"
                           : "a later pass (role " + std::to_string(goal.role) + ") needs the cycle_id of its detect pass";
      return;
    }
    if (const std::string why = cellsight_ros::outputNameProblem(goal.output_file, {".ply", ".pcd"}); !why.empty()) {
      result.status = ScanResult::INVALID_GOAL;
      result.message = "output_file: " + why + " (triangulation writes it into its ~output_dir)";
      return;
    }
    if (!std::isfinite(goal.speed_scale) || goal.speed_scale < 0 || goal.speed_scale > 1) {
      result.status = ScanResult::INVALID_GOAL;
      result.message = "speed_scale must lie in [0, 1] (0: the default 0.1), got " + std::to_string(goal.speed_scale);
      return;
    }
    if (!move_client_.waitForExistence(ros::Duration(30.0))) {
      result.status = ScanResult::ROBOT_TIMEOUT;
      result.message = "service " + move_client_.getService() + " did not appear in 30 s: is the robot driver (or cell_sim) running?";
      return;
    }
    if (!move_client_.isValid()) move_client_ = nh_.serviceClient<cellsight::MoveFlange>("robot/move_flange", true);
    // The first frame is lost if the camera's connection to us is not up yet when the robot
    // reaches the first pose (the camera driver and the robot start together; seen in CI as
    // "no image within 3 s" on frame 0): wait for it, briefly.
    const ros::WallTime connect_deadline = ros::WallTime::now() + ros::WallDuration(5.0);
    while (image_sub_.getNumPublishers() == 0 && ros::ok() && ros::WallTime::now() < connect_deadline)
      ros::WallDuration(0.02).sleep();
    if (image_sub_.getNumPublishers() == 0)
      ROS_WARN("camera_trigger: no camera connected on %s after 5 s; scanning anyway (frames will time out "
               "if it never comes)", image_sub_.getTopic().c_str());
    const bool processing = reset_client_.waitForExistence(ros::Duration(3.0)) && finish_client_.exists();
    if (processing) {
      std_srvs::Trigger t;
      reset_client_.call(t);
    } else {
      ROS_WARN("camera_trigger: scan/reset and scan/finish not available: frames are captured but no cloud is made");
    }
    frames_ = nlohmann::json::array();
    // a cycle's later passes keep their frames beside the first's: frames_pass<k>.json, images/pass<k>_*
    pass_in_cycle_ = goal.role == cellsight::CyclePass::DETECT || goal.cycle_id != cycle_id_ ? 0 : pass_in_cycle_ + 1;
    cycle_id_ = goal.cycle_id;
    if (!save_dir_.empty()) cellsight::makeDirs(save_dir_ + "/images");
    const ros::WallTime t0 = ros::WallTime::now();
    uint32_t captured = 0;
    const bool ok = goal.continuous ? runContinuous(poses, goal.speed_scale, result, captured)
                                    : runStopAndGo(poses, result, captured);
    result.frames = captured;
    result.scan_seconds = (ros::WallTime::now() - t0).toSec();
    writeIndex(name, poses.size(), result.scan_seconds);
    if (!ok) return;
    if (processing) {
      cellsight::FinishScan fin;
      fin.request.output_file = goal.output_file;
      fin.request.expected_frames = captured;
      fin.request.wait_frames_timeout = processing_timeout_;
      fin.request.cycle_id = goal.cycle_id;
      fin.request.role = goal.role;
      fin.request.last_pass = goal.last_pass;
      if (!finish_client_.call(fin)) {
        result.status = ScanResult::PROCESSING_FAILED;
        result.message = "call to scan/finish failed (triangulation node gone?)";
        return;
      }
      if (fin.response.status != cellsight::FinishScan::Response::OK) {
        result.status = ScanResult::PROCESSING_FAILED;
        result.message = fin.response.message;
        return;
      }
      result.points = fin.response.points;
      result.cloud = fin.response.cloud;
      result.output_file = fin.response.output_path;
    }
    result.status = ScanResult::OK;
    result.message = "'" + name + "': " + std::to_string(captured) + " frames, " +
                     std::to_string(result.points) + " points in " + std::to_string(result.scan_seconds) + " s";
  }

  bool move(const Eigen::Isometry3d& pose, double speed_scale, ScanResult& result, double& expected) {
    cellsight::MoveFlange srv;
    srv.request.target.header.frame_id = base_frame_;
    srv.request.target.pose = cellsight_ros::toPoseMsg(pose);
    srv.request.speed_scale = speed_scale;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      in_position_since_ = ros::Time(0);
    }
    // A call that fails in transport (connection dropped under load) is retried once on a new
    // connection; if the first call did reach the robot, the retry finds it already moving.
    bool called = move_client_.call(srv);
    if (!called) {
      ROS_WARN("camera_trigger: call to %s failed; retrying on a new connection", move_client_.getService().c_str());
      ros::WallDuration(0.2).sleep();
      move_client_ = nh_.serviceClient<cellsight::MoveFlange>("robot/move_flange", true);
      called = move_client_.call(srv);
      if (called && srv.response.status == cellsight::MoveFlange::Response::REJECTED_BUSY &&
          srv.response.message.find("moving") != std::string::npos) {
        srv.response.status = cellsight::MoveFlange::Response::OK;
        srv.response.expected_duration = in_position_timeout_;
      }
    }
    if (!called) {
      result.status = ScanResult::ROBOT_REJECTED;
      result.message = "call to " + move_client_.getService() + " failed twice (robot driver gone?)";
      return false;
    }
    if (srv.response.status != cellsight::MoveFlange::Response::OK) {
      result.status = ScanResult::ROBOT_REJECTED;
      result.message = "robot rejected the pose (status " + std::to_string(srv.response.status) + "): " + srv.response.message;
      return false;
    }
    expected = srv.response.expected_duration;
    return true;
  }

  bool waitInPosition(double expected, size_t index, ScanResult& result) {
    std::unique_lock<std::mutex> lock(mutex_);
    const double wait_s = expected + in_position_timeout_;
    if (!cv_.wait_for(lock, std::chrono::duration<double>(wait_s),
                      [&] { return !in_position_since_.isZero() || !ros::ok() || server_.isPreemptRequested(); }) ||
        !ros::ok()) {
      result.status = ScanResult::ROBOT_TIMEOUT;
      result.message = "robot did not report io/in_position within " + std::to_string(wait_s) + " s for pose " +
                       std::to_string(index) + "; check the robot program and the I/O wiring";
      return false;
    }
    if (server_.isPreemptRequested()) {
      result.status = ScanResult::ROBOT_TIMEOUT;
      result.message = "scan preempted";
      return false;
    }
    return true;
  }

  bool runStopAndGo(const Poses& poses, ScanResult& result, uint32_t& captured) {
    cellsight::ScanFeedback fb;
    fb.total = static_cast<uint32_t>(poses.size());
    for (size_t i = 0; i < poses.size() && ros::ok(); ++i) {
      const ros::Time commanded = ros::Time::now();
      double expected = 0;
      if (!move(poses[i], 1.0, result, expected) || !waitInPosition(expected, i, result)) return false;
      // The camera fires on the in-position edge, so its frame is stamped after the command.
      sensor_msgs::ImageConstPtr image;
      {
        std::unique_lock<std::mutex> lock(mutex_);
        if (!cv_.wait_for(lock, std::chrono::duration<double>(capture_timeout_), [&] {
              return (last_image_ && last_image_->header.stamp > commanded) || !ros::ok();
            }) || !ros::ok()) {
          result.status = ScanResult::CAMERA_TIMEOUT;
          result.message = "no image on " + image_sub_.getTopic() + " within " + std::to_string(capture_timeout_) +
                           " s of the in-position signal; is the camera's trigger input wired to the robot output?";
          return false;
        }
        image = last_image_;
      }
      if (storeFrame(image, static_cast<int>(i))) ++captured;
      acknowledge();
      fb.done = static_cast<uint32_t>(i + 1);
      server_.publishFeedback(fb);
    }
    return true;
  }

  bool runContinuous(const Poses& poses, double speed_scale, ScanResult& result, uint32_t& captured) {
    if (!(speed_scale > 0 && speed_scale <= 1)) speed_scale = 0.1;  // 0: the default (NaN never gets here)
    double expected = 0;
    if (!move(poses.front(), 1.0, result, expected) || !waitInPosition(expected, 0, result)) return false;
    acknowledge();
    {
      std::lock_guard<std::mutex> lock(mutex_);
      recording_ = true;
      recorded_.clear();
    }
    cellsight::ScanFeedback fb;
    fb.total = static_cast<uint32_t>(poses.size());
    int index = 0;
    // Frames are paired with tf as they arrive (tf keeps only the last seconds).
    auto drain = [&] {
      std::vector<sensor_msgs::ImageConstPtr> batch;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        batch.swap(recorded_);
      }
      for (const auto& f : batch) {
        if (storeFrame(f, index++)) ++captured;
      }
    };
    bool ok = true;
    for (size_t i = 1; i < poses.size() && ok; ++i) {
      if (!move(poses[i], speed_scale, result, expected)) {
        ok = false;
        break;
      }
      const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(expected + in_position_timeout_);
      while (true) {
        {
          std::unique_lock<std::mutex> lock(mutex_);
          cv_.wait_for(lock, std::chrono::milliseconds(50));
          if (!in_position_since_.isZero()) break;
        }
        drain();
        if (!ros::ok() || server_.isPreemptRequested() || ros::WallTime::now() > deadline) {
          result.status = ScanResult::ROBOT_TIMEOUT;
          result.message = server_.isPreemptRequested() ? "scan preempted"
                                                        : "robot did not report io/in_position for pose " + std::to_string(i);
          ok = false;
          break;
        }
      }
      if (!ok) break;
      acknowledge();
      fb.done = static_cast<uint32_t>(i + 1);
      server_.publishFeedback(fb);
    }
    ros::WallDuration(0.2).sleep();  // the last frame in flight
    {
      std::lock_guard<std::mutex> lock(mutex_);
      recording_ = false;
    }
    drain();
    if (!ok) return false;
    if (captured == 0) {
      result.status = ScanResult::CAMERA_TIMEOUT;
      result.message = "no frames arrived while the robot moved: is the camera free-running?";
      return false;
    }
    return true;
  }

  void onInPosition(const std_msgs::Bool::ConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (msg->data && !in_position_) in_position_since_ = ros::Time::now();
    in_position_ = msg->data;
    cv_.notify_all();
  }

  void onImage(const sensor_msgs::ImageConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    last_image_ = msg;
    if (recording_) recorded_.push_back(msg);
    cv_.notify_all();
  }

  void acknowledge() {
    std_msgs::Bool b;
    b.data = true;
    capture_done_pub_.publish(b);
    ros::WallDuration(0.002).sleep();
    b.data = false;
    capture_done_pub_.publish(b);
  }

  bool storeFrame(const sensor_msgs::ImageConstPtr& image, int index) {
    geometry_msgs::TransformStamped T;
    try {
      T = tf_buffer_.lookupTransform(base_frame_, flange_frame_, image->header.stamp, ros::Duration(tf_timeout_));
    } catch (const tf2::TransformException& e) {
      ROS_ERROR("camera_trigger: frame %d dropped: no %s -> %s at the image stamp %.6f: %s", index,
                base_frame_.c_str(), flange_frame_.c_str(), image->header.stamp.toSec(), e.what());
      diag_.dropped("no flange pose at the image stamp");
      return false;
    }
    nlohmann::json entry;
    entry["index"] = index;
    entry["stamp_ns"] = cellsight_ros::toNanoseconds(image->header.stamp);
    const Eigen::Isometry3d pose = cellsight_ros::fromTransformMsg(T.transform);
    const Eigen::Quaterniond q(pose.linear());
    entry["T_base_flange"] = {{"xyz", {pose.translation().x(), pose.translation().y(), pose.translation().z()}},
                              {"quat", {q.x(), q.y(), q.z(), q.w()}}};
    if (!save_dir_.empty()) {
      cv::Mat out;
      try {
        out = cellsight_ros::fromImageMsg(*image);
      } catch (const std::invalid_argument& e) {
        ROS_ERROR("camera_trigger: frame %d is unusable: %s", index, e.what());
        diag_.dropped("unusable image");
        return false;
      }
      if (image->encoding == sensor_msgs::image_encodings::RGB8) cv::cvtColor(out, out, cv::COLOR_RGB2BGR);
      char name[64];
      std::snprintf(name, sizeof(name), "images/%sframe_%04d.png", passPrefix().c_str(), index);
      if (!cv::imwrite(save_dir_ + "/" + name, out)) {
        ROS_ERROR("camera_trigger: cannot write %s/%s", save_dir_.c_str(), name);
        diag_.dropped("image not written");
        return false;
      }
      entry["image"] = name;
    }
    frames_.push_back(entry);
    diag_.processed();
    return true;
  }

  void writeIndex(const std::string& name, size_t poses, double seconds) {
    if (save_dir_.empty()) return;
    nlohmann::json j;
    j["trajectory"] = name;
    j["poses"] = poses;
    j["frames"] = frames_;
    j["scan_seconds"] = seconds;
    j["cycle_id"] = cycle_id_;
    j["pass"] = pass_in_cycle_;
    const std::string file = pass_in_cycle_ ? "frames_pass" + std::to_string(pass_in_cycle_) + ".json" : "frames.json";
    cellsight::writeFileAtomic(save_dir_ + "/" + file, j.dump(2) + "\n");
  }

  /// "" for a cycle's first pass, "pass<k>_" for its later ones
  std::string passPrefix() const { return pass_in_cycle_ ? "pass" + std::to_string(pass_in_cycle_) + "_" : ""; }

  ros::NodeHandle nh_;
  std::mutex goal_mutex_;
  bool busy_ = false;  // a scan thread is running (guarded by goal_mutex_)
  std::thread worker_;
  cellsight_ros::NodeDiagnostics diag_;
  tf2_ros::Buffer tf_buffer_;
  tf2_ros::TransformListener tf_listener_;
  actionlib::SimpleActionServer<cellsight::ScanAction> server_;
  std::string trajectory_file_, save_dir_;
  std::map<std::string, cellsight::Trajectory> trajectories_;
  std::string base_frame_ = "base_link", flange_frame_ = "flange";
  double in_position_timeout_ = 5.0, capture_timeout_ = 3.0, tf_timeout_ = 0.5, processing_timeout_ = 30.0;
  ros::ServiceClient move_client_, reset_client_, finish_client_;
  ros::Publisher capture_done_pub_;
  ros::Subscriber in_position_sub_;
  image_transport::Subscriber image_sub_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool in_position_ = false;
  ros::Time in_position_since_;
  sensor_msgs::ImageConstPtr last_image_;
  bool recording_ = false;
  std::vector<sensor_msgs::ImageConstPtr> recorded_;
  nlohmann::json frames_ = nlohmann::json::array();
  std::string cycle_id_;   // the latest goal's cycle and the pass it was in it (0: its first)
  int pass_in_cycle_ = 0;
};

}  // namespace

// The goal callback runs the whole scan; the I/O and image callbacks need threads of their own.
CELLSIGHT_NODE(CameraTrigger, "camera_trigger", 3)
