// camera_trigger: the stop-and-go scan cycle of thesis §1 over the cell's digital I/O.
// For each pose of a named trajectory: command the flange (robot/move_flange), wait for the
// robot's "in position" output (io/in_position), take the camera frame it triggered, pair it
// with the flange pose from tf at the image stamp, then acknowledge with io/capture_done so the
// robot may move on. Frames (PNG) and their poses are written to ~save_dir.
#include <cv_bridge/cv_bridge.h>
#include <ros/ros.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/image_encodings.h>
#include <std_msgs/Bool.h>
#include <tf2_ros/buffer.h>
#include <tf2_ros/transform_listener.h>

#include <condition_variable>
#include <mutex>
#include <nlohmann/json.hpp>
#include <opencv2/imgcodecs.hpp>
#include <opencv2/imgproc.hpp>

#include "cellsight/MoveFlange.h"
#include "cellsight/file_io.hpp"
#include "cellsight/ground_truth.hpp"
#include "cellsight/trajectory.hpp"
#include "cellsight_ros/conversions.hpp"
#include "cellsight_ros/params.hpp"

namespace {

class CameraTrigger {
 public:
  CameraTrigger(ros::NodeHandle& nh, ros::NodeHandle& pnh) : tf_listener_(tf_buffer_) {
    trajectory_file_ = cellsight_ros::requireParam<std::string>(
        pnh, "trajectory_file", "YAML of named trajectories, e.g. config/trajectories.yaml");
    trajectory_name_ = cellsight_ros::requireParam<std::string>(
        pnh, "trajectory", "name of the trajectory in ~trajectory_file to run");
    cellsight_ros::param(pnh, "base_frame", base_frame_);
    cellsight_ros::param(pnh, "flange_frame", flange_frame_);
    cellsight_ros::param(pnh, "save_dir", save_dir_);
    cellsight_ros::param(pnh, "in_position_timeout", in_position_timeout_);
    cellsight_ros::param(pnh, "capture_timeout", capture_timeout_);
    cellsight_ros::param(pnh, "tf_timeout", tf_timeout_);
    cellsight_ros::param(pnh, "exit_when_done", exit_when_done_);
    const auto all = cellsight::loadTrajectories(trajectory_file_);
    auto it = all.find(trajectory_name_);
    if (it == all.end()) {
      std::string names;
      for (const auto& kv : all) names += " " + kv.first;
      throw std::runtime_error("trajectory '" + trajectory_name_ + "' not in " + trajectory_file_ +
                               " (has:" + names + ")");
    }
    trajectory_ = it->second;
    if (!save_dir_.empty()) cellsight::makeDirs(save_dir_ + "/images");
    move_client_ = nh.serviceClient<cellsight::MoveFlange>("robot/move_flange");
    capture_done_pub_ = nh.advertise<std_msgs::Bool>("io/capture_done", 10, true);
    in_position_sub_ = nh.subscribe("io/in_position", 10, &CameraTrigger::onInPosition, this);
    image_sub_ = nh.subscribe("scanner_camera/image_raw", 5, &CameraTrigger::onImage, this);
  }

  /// Runs the whole cycle; returns the process exit code.
  int run() {
    if (!move_client_.waitForExistence(ros::Duration(30.0))) {
      ROS_ERROR("camera_trigger: service %s did not appear in 30 s: is the robot driver (or "
                "cell_sim) running?", move_client_.getService().c_str());
      return 1;
    }
    const ros::WallTime t0 = ros::WallTime::now();
    int captured = 0;
    for (size_t i = 0; i < trajectory_.poses.size() && ros::ok(); ++i) {
      cellsight::MoveFlange srv;
      srv.request.target.header.frame_id = base_frame_;
      srv.request.target.pose = cellsight_ros::toPoseMsg(trajectory_.poses[i]);
      const ros::Time commanded = ros::Time::now();
      {
        std::lock_guard<std::mutex> lock(mutex_);
        in_position_since_ = ros::Time(0);
      }
      if (!move_client_.call(srv)) {
        ROS_ERROR("camera_trigger: call to %s failed (robot driver gone?)",
                  move_client_.getService().c_str());
        return 1;
      }
      if (srv.response.status != cellsight::MoveFlange::Response::OK) {
        ROS_ERROR("camera_trigger: pose %zu rejected by the robot (status %d): %s", i,
                  srv.response.status, srv.response.message.c_str());
        return 1;
      }
      // Wait for the rising edge of "in position", then for the frame it triggered.
      std::unique_lock<std::mutex> lock(mutex_);
      const double wait_s = srv.response.expected_duration + in_position_timeout_;
      if (!cv_.wait_for(lock, std::chrono::duration<double>(wait_s),
                        [&] { return !in_position_since_.isZero() || !ros::ok(); }) ||
          !ros::ok()) {
        ROS_ERROR("camera_trigger: robot did not report io/in_position within %.1f s for pose "
                  "%zu; check the robot program and the I/O wiring", wait_s, i);
        return 1;
      }
      // The camera fires on the in-position edge, so its frame is stamped after the command.
      if (!cv_.wait_for(lock, std::chrono::duration<double>(capture_timeout_), [&] {
            return (last_image_ && last_image_->header.stamp > commanded) || !ros::ok();
          }) || !ros::ok()) {
        ROS_ERROR("camera_trigger: no image on %s within %.1f s of the in-position signal; is "
                  "the camera's trigger input wired to the robot output?",
                  image_sub_.getTopic().c_str(), capture_timeout_);
        return 1;
      }
      sensor_msgs::ImageConstPtr image = last_image_;
      lock.unlock();
      if (storeFrame(image, static_cast<int>(i))) ++captured;
      acknowledge();
    }
    const double seconds = (ros::WallTime::now() - t0).toSec();
    writeIndex(seconds);
    ROS_INFO("camera_trigger: trajectory '%s' done: %d of %zu frames captured in %.2f s",
             trajectory_name_.c_str(), captured, trajectory_.poses.size(), seconds);
    return captured == static_cast<int>(trajectory_.poses.size()) ? 0 : 1;
  }

  bool exitWhenDone() const { return exit_when_done_; }

 private:
  void onInPosition(const std_msgs::Bool::ConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    if (msg->data && !in_position_) in_position_since_ = ros::Time::now();
    in_position_ = msg->data;
    cv_.notify_all();
  }

  void onImage(const sensor_msgs::ImageConstPtr& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    last_image_ = msg;
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
      T = tf_buffer_.lookupTransform(base_frame_, flange_frame_, image->header.stamp,
                                     ros::Duration(tf_timeout_));
    } catch (const tf2::TransformException& e) {
      ROS_ERROR("camera_trigger: frame %d dropped: no %s -> %s at the image stamp %.6f: %s",
                index, base_frame_.c_str(), flange_frame_.c_str(), image->header.stamp.toSec(),
                e.what());
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
      cv_bridge::CvImageConstPtr cv;
      try {
        cv = cv_bridge::toCvShare(image);
      } catch (const cv_bridge::Exception& e) {
        ROS_ERROR("camera_trigger: frame %d has an unusable encoding '%s': %s", index,
                  image->encoding.c_str(), e.what());
        return false;
      }
      cv::Mat out = cv->image;
      if (image->encoding == sensor_msgs::image_encodings::RGB8) cv::cvtColor(out, out, cv::COLOR_RGB2BGR);
      char name[64];
      std::snprintf(name, sizeof(name), "images/frame_%04d.png", index);
      if (!cv::imwrite(save_dir_ + "/" + name, out)) {
        ROS_ERROR("camera_trigger: cannot write %s/%s", save_dir_.c_str(), name);
        return false;
      }
      entry["image"] = name;
    }
    frames_.push_back(entry);
    return true;
  }

  void writeIndex(double seconds) {
    if (save_dir_.empty()) return;
    nlohmann::json j;
    j["trajectory"] = trajectory_name_;
    j["poses"] = trajectory_.poses.size();
    j["frames"] = frames_;
    j["scan_seconds"] = seconds;
    cellsight::writeFileAtomic(save_dir_ + "/frames.json", j.dump(2) + "\n");
  }

  tf2_ros::Buffer tf_buffer_;
  tf2_ros::TransformListener tf_listener_;
  std::string trajectory_file_, trajectory_name_, save_dir_;
  std::string base_frame_ = "base_link", flange_frame_ = "flange";
  double in_position_timeout_ = 5.0, capture_timeout_ = 3.0, tf_timeout_ = 0.5;
  bool exit_when_done_ = true;
  cellsight::Trajectory trajectory_;
  ros::ServiceClient move_client_;
  ros::Publisher capture_done_pub_;
  ros::Subscriber in_position_sub_, image_sub_;
  std::mutex mutex_;
  std::condition_variable cv_;
  bool in_position_ = false;
  ros::Time in_position_since_;
  sensor_msgs::ImageConstPtr last_image_;
  nlohmann::json frames_ = nlohmann::json::array();
};

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "camera_trigger");
  ros::NodeHandle nh, pnh("~");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  int rc = 0;
  try {
    CameraTrigger trigger(nh, pnh);
    rc = trigger.run();
    if (!trigger.exitWhenDone()) ros::waitForShutdown();
  } catch (const std::exception& e) {
    ROS_FATAL("camera_trigger: %s", e.what());
    rc = 1;
  }
  ros::shutdown();
  return rc;
}
