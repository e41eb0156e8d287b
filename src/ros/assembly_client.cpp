// assembly_client: runs the assembly on a cell (or the simulated one) once the parts are located:
// asks grasp_planner for the next part (~plan with object ""), has the robot execute the checked
// trajectory (robot/execute_plan), waits for io/in_position, tells the planner the part is placed,
// and goes on until no part of the assembly is left or none plans; refusals are reported with
// their reasons. Writes every step to ~result_file (JSON) and exits 0 when every planned part was
// executed. `rosrun cellsight assembly_client _result_file:=assembly.json`
#include <ros/ros.h>
#include <std_msgs/Bool.h>

#include <atomic>
#include <map>
#include <nlohmann/json.hpp>

#include "cellsight/DetectionArray.h"
#include "cellsight/ExecutePlan.h"
#include "cellsight/PlanGrasp.h"
#include "cellsight/common/file_io.hpp"
#include "cellsight_ros/params.hpp"

int main(int argc, char** argv) {
  ros::init(argc, argv, "assembly_client");
  ros::NodeHandle nh, pnh("~");
  std::string result_file;
  double time_scale = 1.0, timeout = 300.0, detections_timeout = 600.0;
  int max_parts = 20;
  cellsight_ros::param(pnh, "result_file", result_file);
  cellsight_ros::param(pnh, "time_scale", time_scale);
  cellsight_ros::param(pnh, "timeout", timeout);
  cellsight_ros::param(pnh, "detections_timeout", detections_timeout);
  cellsight_ros::param(pnh, "max_parts", max_parts);
  // io/in_position edges, counted: the motion has started (false) and ended (true)
  std::atomic<int> falls{0}, rises{0};
  ros::Subscriber io = nh.subscribe<std_msgs::Bool>("io/in_position", 10, [&](const std_msgs::BoolConstPtr& m) {
    ++(m->data ? rises : falls);
  });
  ros::AsyncSpinner spinner(1);
  spinner.start();
  ros::ServiceClient plan_srv = nh.serviceClient<cellsight::PlanGrasp>("grasp_planner/plan");
  ros::ServiceClient exec_srv = nh.serviceClient<cellsight::ExecutePlan>("robot/execute_plan");
  for (auto* s : {&plan_srv, &exec_srv}) {
    if (!s->waitForExistence(ros::Duration(120.0))) {
      ROS_ERROR("assembly_client: service %s not available within 120 s", s->getService().c_str());
      return 1;
    }
  }
  // the parts must have been located first, on every pass of the cycle
  const ros::Time located_by = ros::Time::now() + ros::Duration(detections_timeout);
  for (;;) {
    const auto d = ros::topic::waitForMessage<cellsight::DetectionArray>("detections", nh, located_by - ros::Time::now());
    if (d && d->final) break;
    if (!d || ros::Time::now() >= located_by || !ros::ok()) {
      ROS_ERROR("assembly_client: no detections of a whole cycle (its last pass) within %.0f s: scan and locate first",
                detections_timeout);
      return 1;
    }
  }
  nlohmann::json steps = nlohmann::json::array();
  auto write = [&](bool done) {
    if (result_file.empty()) return;
    cellsight::writeFileAtomic(result_file, nlohmann::json{{"steps", steps}, {"done", done}}.dump(2) + "\n");
  };
  const ros::WallTime t_start = ros::WallTime::now();
  bool failed = false;
  std::map<std::string, std::string> refused;  // parts passed over, with the latest reason
  auto note_refusals = [&](const cellsight::GraspPlan& p) {
    for (const std::string& r : p.passed_over) {
      const std::string object = r.substr(0, r.find(':'));
      if (!refused.count(object)) ROS_WARN("assembly_client: passed over %s", r.c_str());
      refused[object] = r;
    }
  };
  for (int k = 0; k < max_parts && ros::ok(); ++k) {
    cellsight::PlanGrasp plan;
    const ros::WallTime t0 = ros::WallTime::now();
    if (!plan_srv.call(plan)) {
      ROS_ERROR("assembly_client: the call to %s failed", plan_srv.getService().c_str());
      failed = true;
      break;
    }
    const cellsight::GraspPlan& p = plan.response.plan;
    note_refusals(p);
    refused.erase(p.object);
    nlohmann::json step = {{"object", p.object}, {"model", p.model}, {"status", p.status}, {"reason", p.reason},
                           {"plan_seconds", p.plan_seconds}, {"service_seconds", (ros::WallTime::now() - t0).toSec()},
                           {"sampled", static_cast<bool>(p.sampled)}, {"candidates_tried", p.candidates_tried},
                           {"grasp_source", p.grasp_source}};
    if (p.status == cellsight::GraspPlan::NOTHING_LEFT) {
      ROS_INFO("assembly_client: %s", plan.response.message.c_str());
      break;
    }
    if (p.status != cellsight::GraspPlan::OK) {
      ROS_INFO("assembly_client: no further part plans: %s", plan.response.message.c_str());
      step["executed"] = false;
      steps.push_back(step);
      break;
    }
    step["target"] = {{"xyz", {p.target.position.x, p.target.position.y, p.target.position.z}},
                      {"quat", {p.target.orientation.x, p.target.orientation.y, p.target.orientation.z, p.target.orientation.w}}};
    const int falls_before = falls, rises_before = rises;
    cellsight::ExecutePlan exec;
    exec.request.plan = p;
    exec.request.time_scale = time_scale;
    if (!exec_srv.call(exec) || exec.response.status != cellsight::ExecutePlan::Response::OK) {
      ROS_ERROR("assembly_client: the robot refused the plan of '%s': %s", p.object.c_str(), exec.response.message.c_str());
      step["executed"] = false;
      step["execute_message"] = exec.response.message;
      steps.push_back(step);
      failed = true;
      break;
    }
    // the robot leaves its position, then reports in position again after the motion
    const ros::WallTime t1 = ros::WallTime::now();
    auto moved = [&] { return falls > falls_before && rises > rises_before; };
    while (ros::ok() && !moved() && (ros::WallTime::now() - t1).toSec() < exec.response.expected_duration + timeout) {
      ros::WallDuration(0.02).sleep();
    }
    if (!moved()) {
      ROS_ERROR("assembly_client: the robot did not report in position after '%s'", p.object.c_str());
      failed = true;
      break;
    }
    step["executed"] = true;
    step["motion_seconds"] = (ros::WallTime::now() - t1).toSec();
    cellsight::PlanGrasp placed;
    placed.request.object = p.object;
    placed.request.placed = true;
    if (!plan_srv.call(placed) || placed.response.plan.status != cellsight::GraspPlan::OK) {
      ROS_ERROR("assembly_client: the planner did not take '%s' as placed: %s", p.object.c_str(), placed.response.message.c_str());
      failed = true;
    }
    steps.push_back(step);
    write(false);
    ROS_INFO("assembly_client: '%s' placed (%.0f ms planning, %.1f s motion)", p.object.c_str(), p.plan_seconds * 1e3,
             step["motion_seconds"].get<double>());
    if (failed) break;
  }
  // the parts that never planned, with their reasons (the cycle went on without them)
  for (const auto& [object, r] : refused) {
    const size_t a = r.find(": "), b = r.find(": ", a + 2);
    steps.push_back({{"object", object}, {"model", ""}, {"status", r.substr(a + 2, b - a - 2)},
                     {"reason", b == std::string::npos ? r : r.substr(b + 2)}, {"plan_seconds", 0.0}, {"executed", false}});
  }
  write(!failed);
  ROS_INFO("assembly_client: done in %.1f s", (ros::WallTime::now() - t_start).toSec());
  return failed ? 1 : 0;
}
