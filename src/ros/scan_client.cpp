// scan_client: sends one Scan goal, prints progress, writes the result as JSON and exits with
// 0 on success. `rosrun cellsight scan_client _trajectory:=demo_sweep _output_file:=scan.ply`
#include <actionlib/client/simple_action_client.h>
#include <ros/ros.h>

#include <nlohmann/json.hpp>

#include "cellsight/ScanAction.h"
#include "cellsight/common/file_io.hpp"
#include "cellsight_ros/params.hpp"

int main(int argc, char** argv) {
  ros::init(argc, argv, "scan_client");
  ros::NodeHandle pnh("~");
  cellsight::ScanGoal goal;
  std::string result_file;
  double timeout = 600.0;
  goal.trajectory = "demo_sweep";
  cellsight_ros::param(pnh, "trajectory", goal.trajectory);
  bool continuous = false;
  cellsight_ros::param(pnh, "continuous", continuous);
  goal.continuous = continuous;
  cellsight_ros::param(pnh, "speed_scale", goal.speed_scale);
  cellsight_ros::param(pnh, "output_file", goal.output_file);
  cellsight_ros::param(pnh, "result_file", result_file);
  cellsight_ros::param(pnh, "timeout", timeout);
  double start_delay = 0.0;  // e.g. to let a recorder subscribe first
  cellsight_ros::param(pnh, "start_delay", start_delay);
  actionlib::SimpleActionClient<cellsight::ScanAction> client("scan", true);
  if (!client.waitForServer(ros::Duration(60.0))) {
    ROS_ERROR("scan_client: no Scan action server on %s within 60 s: is camera_trigger running?",
              ros::names::resolve("scan").c_str());
    return 1;
  }
  if (start_delay > 0) ros::WallDuration(start_delay).sleep();
  client.sendGoal(goal, {}, {}, [](const cellsight::ScanFeedbackConstPtr& fb) {
    ROS_INFO_THROTTLE(2.0, "scan_client: %u / %u", fb->done, fb->total);
  });
  if (!client.waitForResult(ros::Duration(timeout))) {
    client.cancelGoal();
    ROS_ERROR("scan_client: no result within %.0f s; goal cancelled", timeout);
    return 1;
  }
  const auto result = client.getResult();
  const bool ok = client.getState() == actionlib::SimpleClientGoalState::SUCCEEDED;
  if (!result_file.empty()) {
    nlohmann::json j = {{"status", result->status},       {"message", result->message},
                        {"frames", result->frames},       {"points", result->points},
                        {"scan_seconds", result->scan_seconds}, {"output_file", result->output_file},
                        {"trajectory", goal.trajectory},  {"continuous", static_cast<bool>(goal.continuous)}};
    cellsight::writeFileAtomic(result_file, j.dump(2) + "\n");
  }
  if (ok) {
    ROS_INFO("scan_client: %s", result->message.c_str());
  } else {
    ROS_ERROR("scan_client: scan failed (status %u): %s", result->status, result->message.c_str());
  }
  return ok ? 0 : 1;
}
