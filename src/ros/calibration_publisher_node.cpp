// calibration_publisher: the single source of truth for calibrated frames. Loads every
// calibration YAML of a folder (transforms → static tf; camera_info files validated) and
// publishes them with tf2_ros::StaticTransformBroadcaster. ~reload re-reads the folder; a bad
// file leaves the transforms already published in place.
#include <ros/ros.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/static_transform_broadcaster.h>

#include "cellsight/common/calibration.hpp"
#include "cellsight/common/errors.hpp"
#include "cellsight_ros/conversions.hpp"
#include "cellsight_ros/node.hpp"
#include "cellsight_ros/diagnostics.hpp"
#include "cellsight_ros/params.hpp"

#include <ctime>
#include <mutex>

namespace {

class CalibrationPublisher {
 public:
  CalibrationPublisher(ros::NodeHandle& nh, ros::NodeHandle& pnh)
      : diag_(nh, pnh, "calibration_publisher", "calibration loads", 2.0) {
    diag_.addValue("oldest calibration age [days]", [this] {
      std::lock_guard<std::mutex> lock(mutex_);
      return oldest_ > 0 ? std::to_string((std::time(nullptr) - oldest_) / 86400.0) : std::string("unknown");
    });
    folder_ = cellsight_ros::requireParam<std::string>(
        pnh, "calibration_dir", "folder of calibration YAML files, e.g. out/demo/calibration");
    if (folder_.empty())
      throw std::runtime_error("no calibration folder: give the cell's, e.g. roslaunch cellsight cell.launch "
                               "calibration_dir:=/path/to/calibration (camera_info and transform YAMLs, as "
                               "cellsight_calibrate writes them)");
    double wait_seconds = 0.0;
    cellsight_ros::param(pnh, "wait_seconds", wait_seconds);
    // With ~wait_seconds > 0 the folder may appear later (e.g. written by the simulator at its
    // start); a folder that exists but holds a bad file is an error at once.
    const ros::WallTime deadline = ros::WallTime::now() + ros::WallDuration(wait_seconds);
    while (true) {
      try {
        publish(cellsight::loadCalibrationFolder(folder_));
        break;
      } catch (const cellsight::ConfigError& e) {
        const bool missing = std::string(e.what()).find("cannot be opened") != std::string::npos;
        if (!missing || ros::WallTime::now() > deadline || !ros::ok()) throw;
        ros::WallDuration(0.2).sleep();
      }
    }
    reload_srv_ = pnh.advertiseService("reload", &CalibrationPublisher::onReload, this);
  }

 private:
  void publish(const cellsight::CalibrationSet& set) {
    if (set.transforms.empty()) {
      throw std::runtime_error(folder_ + ": no transform calibration found (expected files with "
                                         "parent_frame / child_frame)");
    }
    std::vector<geometry_msgs::TransformStamped> msgs;
    const ros::Time now = ros::Time::now();
    for (const auto& [file, cal] : set.transforms) {
      msgs.push_back(cellsight_ros::toTransformStamped(cal, now));
      ROS_INFO("calibration_publisher: %s -> %s from %s (%s, residual %.3g)",
               cal.parent_frame.c_str(), cal.child_frame.c_str(), file.c_str(),
               cal.method.c_str(), cal.residual_rms);
    }
    for (const auto& f : set.camera_files) {
      ROS_INFO("calibration_publisher: camera intrinsics %s are valid", f.c_str());
    }
    broadcaster_.sendTransform(msgs);
    std::time_t oldest = 0;
    for (const auto& [file, cal] : set.transforms) {
      diag_.set(cal.parent_frame + " -> " + cal.child_frame, file + ", " + (cal.date.empty() ? "undated" : cal.date));
      std::tm tm{};
      if (!cal.date.empty() && strptime(cal.date.c_str(), "%Y-%m-%dT%H:%M:%S", &tm)) {
        const std::time_t t = timegm(&tm);
        if (oldest == 0 || t < oldest) oldest = t;
      }
    }
    {
      std::lock_guard<std::mutex> lock(mutex_);
      oldest_ = oldest;
    }
    diag_.processed();
  }

  bool onReload(std_srvs::Trigger::Request&, std_srvs::Trigger::Response& res) {
    try {
      publish(cellsight::loadCalibrationFolder(folder_));
      res.success = true;
      res.message = "reloaded " + folder_;
    } catch (const std::exception& e) {
      res.success = false;
      res.message = std::string("reload refused, previous calibration kept: ") + e.what();
      ROS_ERROR("calibration_publisher: %s", res.message.c_str());
      diag_.dropped("reload refused (bad calibration file)");
    }
    return true;
  }

  cellsight_ros::NodeDiagnostics diag_;
  std::mutex mutex_;
  std::time_t oldest_ = 0;  // date of the oldest loaded calibration
  std::string folder_;
  tf2_ros::StaticTransformBroadcaster broadcaster_;
  ros::ServiceServer reload_srv_;
};

}  // namespace

CELLSIGHT_NODE(CalibrationPublisher, "calibration_publisher", 1)
