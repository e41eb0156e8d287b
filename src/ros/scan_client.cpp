// scan_client: scans one cell cycle: one Scan goal per pass, in order (a detect pass, then passes
// that add detections or refine, all with one cycle id), prints progress, writes the result as
// JSON and exits with 0 when every pass succeeded. A failed pass ends the cycle there.
//   rosrun cellsight scan_client _trajectory:=demo_sweep _output_file:=scan.ply          (one pass)
//   rosrun cellsight scan_client _passes:="demo_sweep:detect reverse_sweep:add_detections cross_sweep:refine"
#include <actionlib/client/simple_action_client.h>
#include <ros/ros.h>

#include <nlohmann/json.hpp>
#include <sstream>

#include "cellsight/CyclePass.h"
#include "cellsight/ScanAction.h"
#include "cellsight/common/file_io.hpp"
#include "cellsight_ros/params.hpp"
#include "cellsight_ros/scan_messages.hpp"

namespace {

struct Pass {
  std::string trajectory;
  uint8_t role = cellsight::CyclePass::DETECT;
};

/// "trajectory:role ..." (role detect, add_detections or refine; the first must detect).
std::vector<Pass> parsePasses(const std::string& text) {
  std::vector<Pass> out;
  std::istringstream in(text);
  for (std::string word; in >> word;) {
    const size_t colon = word.find(':');
    Pass p{word.substr(0, colon)};
    const std::string role = colon == std::string::npos ? "detect" : word.substr(colon + 1);
    if (role == "add_detections") p.role = cellsight::CyclePass::ADD_DETECTIONS;
    else if (role == "refine") p.role = cellsight::CyclePass::REFINE;
    else if (role != "detect") throw std::invalid_argument("pass '" + word + "': role must be detect, add_detections or refine");
    if (p.trajectory.empty()) throw std::invalid_argument("pass '" + word + "' names no trajectory");
    if ((p.role == cellsight::CyclePass::DETECT) != out.empty())
      throw std::invalid_argument("'" + text + "': the first pass, and only it, detects");
    out.push_back(p);
  }
  if (out.empty()) throw std::invalid_argument("no pass given");
  return out;
}

}  // namespace

int main(int argc, char** argv) {
  ros::init(argc, argv, "scan_client");
  ros::NodeHandle pnh("~");
  std::string trajectory, passes_text, cycle_id, output_file, result_file;
  double timeout = 600.0, speed_scale = 0.0;
  bool continuous = false;
  cellsight_ros::param(pnh, "trajectory", trajectory);
  cellsight_ros::param(pnh, "passes", passes_text);
  cellsight_ros::param(pnh, "cycle_id", cycle_id);
  cellsight_ros::param(pnh, "continuous", continuous);
  cellsight_ros::param(pnh, "speed_scale", speed_scale);
  cellsight_ros::param(pnh, "output_file", output_file);
  cellsight_ros::param(pnh, "result_file", result_file);
  cellsight_ros::param(pnh, "timeout", timeout);
  double start_delay = 0.0;  // e.g. to let a recorder subscribe first
  cellsight_ros::param(pnh, "start_delay", start_delay);
  std::vector<Pass> passes;
  try {
    passes = parsePasses(trajectory.empty() ? (passes_text.empty() ? "demo_sweep" : passes_text) : trajectory);
  } catch (const std::exception& e) {
    ROS_ERROR("scan_client: ~passes: %s (e.g. \"demo_sweep:detect reverse_sweep:add_detections cross_sweep:refine\")", e.what());
    return 2;
  }
  if (!trajectory.empty() && !passes_text.empty())
    ROS_WARN("scan_client: ~trajectory '%s' given: one pass; ~passes is ignored", trajectory.c_str());
  // a cycle of several passes needs an id; a single pass scans on its own unless one is given
  if (cycle_id.empty() && passes.size() > 1) cycle_id = "cycle_" + std::to_string(ros::WallTime::now().toNSec());
  actionlib::SimpleActionClient<cellsight::ScanAction> client("scan", true);
  if (!client.waitForServer(ros::Duration(60.0))) {
    ROS_ERROR("scan_client: no Scan action server on %s within 60 s: is camera_trigger running?",
              ros::names::resolve("scan").c_str());
    return 1;
  }
  if (start_delay > 0) ros::WallDuration(start_delay).sleep();
  nlohmann::json results = nlohmann::json::array();
  uint32_t frames = 0;
  double seconds = 0;
  bool ok = true;
  for (size_t k = 0; k < passes.size() && ok && ros::ok(); ++k) {
    cellsight::ScanGoal goal;
    goal.trajectory = passes[k].trajectory;
    goal.continuous = continuous;
    goal.speed_scale = speed_scale;
    goal.output_file = cellsight_ros::passOutputFile(output_file, k);
    goal.cycle_id = cycle_id;
    goal.role = passes[k].role;
    goal.last_pass = k + 1 == passes.size();
    client.sendGoal(goal, {}, {}, [&](const cellsight::ScanFeedbackConstPtr& fb) {
      ROS_INFO_THROTTLE(2.0, "scan_client: pass %zu/%zu (%s): %u / %u", k + 1, passes.size(), goal.trajectory.c_str(), fb->done,
                        fb->total);
    });
    if (!client.waitForResult(ros::Duration(timeout))) {
      client.cancelGoal();
      ROS_ERROR("scan_client: pass %zu (%s): no result within %.0f s; goal cancelled, the cycle ends here", k + 1,
                goal.trajectory.c_str(), timeout);
      return 1;
    }
    const auto result = client.getResult();
    ok = client.getState() == actionlib::SimpleClientGoalState::SUCCEEDED;
    results.push_back({{"status", result->status},       {"message", result->message},
                       {"frames", result->frames},       {"points", result->points},
                       {"scan_seconds", result->scan_seconds}, {"output_file", result->output_file},
                       {"trajectory", goal.trajectory},  {"role", goal.role}});
    frames += result->frames;
    seconds += result->scan_seconds;
    if (ok) ROS_INFO("scan_client: pass %zu/%zu: %s", k + 1, passes.size(), result->message.c_str());
    else ROS_ERROR("scan_client: pass %zu (%s) failed (status %u): %s; the cycle ends here", k + 1, goal.trajectory.c_str(),
                   result->status, result->message.c_str());
  }
  if (!result_file.empty() && !results.empty()) {
    // the first pass's fields at the top (the scan the scanner figures are taken on), every pass below
    nlohmann::json j = results.front();
    j["continuous"] = continuous;
    j["status"] = results.back()["status"];  // 0 when every pass succeeded
    j["message"] = results.back()["message"];
    j["cycle_id"] = cycle_id;
    j["passes"] = results;
    j["cycle_frames"] = frames;
    j["cycle_scan_seconds"] = seconds;
    cellsight::writeFileAtomic(result_file, j.dump(2) + "\n");
  }
  return ok ? 0 : 1;
}
