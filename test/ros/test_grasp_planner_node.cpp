// The grasp_planner node: refusals before detections, scan and joint states (with the reason,
// the node answering on); a plan for the demo cell's next part (a checked, time-parameterised
// trajectory starting at the joint state); placed parts leave the order; unknown objects and
// models, detections in a frame without a transform, non-finite joint states.
#include <gtest/gtest.h>

#include <ros/package.h>
#include <ros/ros.h>
#include <sensor_msgs/JointState.h>
#include <visualization_msgs/MarkerArray.h>

#include <atomic>
#include <cmath>
#include <thread>

#include "cellsight/DetectionArray.h"
#include "cellsight/PlanGrasp.h"
#include "cellsight/localization/localization_eval.hpp"
#include "cellsight/planning/arm_model.hpp"
#include "cellsight/sim/scene.hpp"
#include "cellsight_ros/conversions.hpp"

namespace {

cellsight::PlanGrasp call(ros::ServiceClient& c, const std::string& object, bool placed = false) {
  cellsight::PlanGrasp srv;
  srv.request.object = object;
  srv.request.placed = placed;
  EXPECT_TRUE(c.call(srv));
  return srv;
}

}  // namespace

TEST(GraspPlannerNode, PlansRefusesAndKeepsAnswering) {
  ros::NodeHandle nh;
  auto plan = nh.serviceClient<cellsight::PlanGrasp>("grasp_planner/plan");
  ASSERT_TRUE(plan.waitForExistence(ros::Duration(60)));
  auto r = call(plan, "");
  EXPECT_EQ(r.response.plan.status, cellsight::GraspPlan::BAD_INPUT);
  EXPECT_NE(r.response.message.find("no detections"), std::string::npos) << r.response.message;

  // the demo cell's parts, located where they are, plus a part of a model the planner does not know
  const std::string root = ros::package::getPath("cellsight");
  const cellsight::Scene scene = cellsight::loadScene(root + "/config/scenes/demo.yaml");
  cellsight::DetectionArray dets;
  dets.header.frame_id = "base_link";
  dets.header.stamp = ros::Time::now();
  cellsight::ScanCloud cloud;
  for (const auto& o : scene.objects) {
    cellsight::Detection d;
    d.model = o.model;
    d.name = "object/" + o.name;
    d.pose = cellsight_ros::toPoseMsg(o.T_base_object);
    dets.detections.push_back(d);
    const cellsight::ScanCloud v = cellsight::singleViewCloud(cellsight::loadMesh(o.info.mesh_file), o.T_base_object,
                                                              Eigen::Vector3f(0.52f, 0.f, 0.62f), 0.002, 2e-5, 3);
    for (size_t i = 0; i < v.size(); ++i) cloud.append(v.points[i], 0.f);
  }
  cellsight::Detection mystery;
  mystery.model = "mystery";
  mystery.name = "object/mystery_0";
  mystery.pose = cellsight_ros::toPoseMsg(Eigen::Isometry3d(Eigen::Translation3d(0.45, 0.2, 0.0)));
  dets.detections.push_back(mystery);
  auto det_pub = nh.advertise<cellsight::DetectionArray>("detections", 1, true);
  auto cloud_pub = nh.advertise<sensor_msgs::PointCloud2>("scan/cloud", 1, true);
  auto joints_pub = nh.advertise<sensor_msgs::JointState>("joint_states", 10);
  det_pub.publish(dets);
  r = call(plan, "");
  for (int i = 0; i < 50 && r.response.message.find("no detections") != std::string::npos; ++i) {
    ros::WallDuration(0.1).sleep();
    r = call(plan, "");
  }
  EXPECT_NE(r.response.message.find("no scan"), std::string::npos) << r.response.message;
  sensor_msgs::PointCloud2 cm = cellsight_ros::toCloudMsg(cloud, dets.header.stamp);
  cm.header.frame_id = "base_link";
  cloud_pub.publish(cm);
  ros::WallDuration(0.5).sleep();
  r = call(plan, "");
  EXPECT_EQ(r.response.plan.status, cellsight::GraspPlan::BAD_INPUT);
  EXPECT_NE(r.response.message.find("no joint state"), std::string::npos) << r.response.message;

  // the robot at home, as a driver publishes it; a non-finite message in between is ignored
  const cellsight::ArmModel arm = cellsight::ArmModel::fromUrdfFile(root + "/urdf/cellsight_arm.urdf");
  const cellsight::JointVector home = (cellsight::JointVector() << 0.0, 0.5, 0.64, 0.0, 0.43, 0.0).finished();
  std::atomic<bool> run{true};
  std::thread driver([&] {
    while (run && ros::ok()) {
      sensor_msgs::JointState js;
      js.header.stamp = ros::Time::now();
      for (int j = 0; j < 6; ++j) {
        js.name.push_back(arm.jointNames()[static_cast<size_t>(j)]);
        js.position.push_back(home[j]);
      }
      joints_pub.publish(js);
      js.position[2] = std::nan("");
      joints_pub.publish(js);
      js.position[2] = home[2];
      joints_pub.publish(js);
      ros::WallDuration(0.05).sleep();
    }
  });
  ros::WallDuration(0.5).sleep();
  // a malformed scan (data shorter than its sizes) is dropped: the good one before it stays in use
  sensor_msgs::PointCloud2 broken = cm;
  broken.data.resize(broken.data.size() / 2);
  cloud_pub.publish(broken);
  ros::WallDuration(0.5).sleep();
  r = call(plan, "");
  ASSERT_EQ(r.response.plan.status, cellsight::GraspPlan::OK) << r.response.message;
  const cellsight::GraspPlan& p = r.response.plan;
  EXPECT_EQ(p.model, "housing");  // the first of config/assembly.yaml's order
  EXPECT_EQ(p.object, "housing");
  ASSERT_EQ(p.pose_names.size(), 6u);
  EXPECT_EQ(p.pose_names[1], "grasp");
  const cellsight::TimedTrajectory t = cellsight_ros::fromTrajectoryMsg(p.trajectory, arm.jointNames());
  EXPECT_LT(cellsight::jointDistance(t.positions.front(), home), 1e-9);
  EXPECT_LT(p.grasp_index, p.release_index);
  EXPECT_LT(p.release_index, t.positions.size());
  // the grasp point of the trajectory is the plan's grasp pose
  const Eigen::Isometry3d tcp = arm.fk(t.positions[p.grasp_index]) * arm.toolTcp();
  EXPECT_LT((tcp.translation() - cellsight_ros::fromPoseMsg(p.poses[1]).translation()).norm(), 1e-5);
  EXPECT_GT(p.grip_width, 0.0);
  EXPECT_GT(p.plan_seconds, 0.0);
  auto markers = ros::topic::waitForMessage<visualization_msgs::MarkerArray>("grasp_planner/markers", nh, ros::Duration(5));
  ASSERT_TRUE(markers);

  // carried out: the next plan is for the next part of the order; the placed one is refused
  r = call(plan, "housing", true);
  EXPECT_EQ(r.response.plan.status, cellsight::GraspPlan::OK) << r.response.message;
  r = call(plan, "");
  EXPECT_EQ(r.response.plan.status, cellsight::GraspPlan::OK) << r.response.message;
  EXPECT_EQ(r.response.plan.model, "flanged_shaft");
  r = call(plan, "object/housing");
  EXPECT_EQ(r.response.plan.status, cellsight::GraspPlan::BAD_INPUT);
  EXPECT_NE(r.response.plan.reason.find("already placed"), std::string::npos) << r.response.plan.reason;
  r = call(plan, "housing", true);  // no OK plan left to mark
  EXPECT_EQ(r.response.plan.status, cellsight::GraspPlan::BAD_INPUT);
  // unknown names and models, parts outside the assembly
  r = call(plan, "nothing_here");
  EXPECT_EQ(r.response.plan.status, cellsight::GraspPlan::BAD_INPUT);
  EXPECT_NE(r.response.message.find("no located part"), std::string::npos) << r.response.message;
  r = call(plan, "mystery_0");
  EXPECT_EQ(r.response.plan.status, cellsight::GraspPlan::UNKNOWN_MODEL) << r.response.message;
  r = call(plan, "sphere");
  EXPECT_EQ(r.response.plan.status, cellsight::GraspPlan::NOT_IN_ASSEMBLY) << r.response.message;

  // detections in a frame nothing transforms: dropped with the reason, the node answers on
  cellsight::DetectionArray lost = dets;
  lost.header.frame_id = "nowhere";
  lost.header.stamp = ros::Time::now();
  det_pub.publish(lost);
  ros::WallDuration(0.5).sleep();
  r = call(plan, "");
  EXPECT_EQ(r.response.plan.status, cellsight::GraspPlan::BAD_INPUT);
  EXPECT_NE(r.response.message.find("no transform"), std::string::npos) << r.response.message;
  dets.header.stamp = ros::Time::now();
  det_pub.publish(dets);
  ros::WallDuration(0.5).sleep();
  r = call(plan, "");
  EXPECT_EQ(r.response.plan.status, cellsight::GraspPlan::OK) << r.response.message;
  run = false;
  driver.join();
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_grasp_planner_node");
  ros::AsyncSpinner spinner(1);
  spinner.start();
  return RUN_ALL_TESTS();
}
