// Diagnostics every node publishes on /diagnostics (diagnostic_updater; rqt_runtime_monitor and
// rviz's diagnostics panels show them): how many inputs were processed and dropped, the drop
// reasons with their counts, the input rate, the processing time of the last input, and any
// key/values a node adds (e.g. calibration age). The status is WARN after a drop within the
// last period and ERROR when nothing has been processed while inputs were dropped.
#pragma once
#include <diagnostic_updater/diagnostic_updater.h>
#include <ros/ros.h>

#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <vector>

namespace cellsight_ros {

class NodeDiagnostics {
 public:
  /// `what` names the unit counted (e.g. "frames", "scans"); published at `period` seconds.
  NodeDiagnostics(ros::NodeHandle& nh, ros::NodeHandle& pnh, const std::string& name, const std::string& what,
                  double period = 1.0);

  /// One input processed, taking `seconds` of processing.
  void processed(double seconds = 0.0);
  /// One input dropped; `reason` is a short stable phrase ("no tf at the image stamp").
  void dropped(const std::string& reason);
  /// A value shown with the status (replaced at each call).
  void set(const std::string& key, const std::string& value);
  /// Computed at each publication (e.g. the age of a calibration).
  void addValue(const std::string& key, std::function<std::string()> fn);

 private:
  void produce(diagnostic_updater::DiagnosticStatusWrapper& stat);

  diagnostic_updater::Updater updater_;
  ros::Timer timer_;
  std::string what_;
  std::mutex mutex_;
  uint64_t processed_ = 0, dropped_ = 0;
  uint64_t processed_at_last_ = 0, dropped_at_last_ = 0;
  ros::WallTime last_publication_ = ros::WallTime::now();
  double last_seconds_ = 0.0, max_seconds_ = 0.0;
  std::map<std::string, uint64_t> reasons_;
  std::map<std::string, std::string> values_;
  std::vector<std::pair<std::string, std::function<std::string()>>> computed_;
};

}  // namespace cellsight_ros
