#include <actionlib/client/simple_action_client.h>
#include <gtest/gtest.h>
#include <ros/ros.h>

#include <cmath>

#include "cellsight/MoveFlange.h"
#include "cellsight/CyclePass.h"
#include "cellsight/ScanAction.h"

namespace {
// A robot that accepts every pose and never reaches it (a stuck program, a broken I/O wire).
bool stuckRobot(cellsight::MoveFlange::Request&, cellsight::MoveFlange::Response& res) {
  res.status = cellsight::MoveFlange::Response::OK;
  res.message = "moving";
  res.expected_duration = 0.2;
  return true;
}
}  // namespace

TEST(ScanBadInput, UnknownTrajectoryIsRefused) {
  actionlib::SimpleActionClient<cellsight::ScanAction> client("scan", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(30)));
  cellsight::ScanGoal goal;
  goal.trajectory = "no_such_trajectory";
  client.sendGoal(goal);
  ASSERT_TRUE(client.waitForResult(ros::Duration(20)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::ABORTED);
  EXPECT_EQ(client.getResult()->status, cellsight::ScanResult::INVALID_GOAL);
  EXPECT_NE(client.getResult()->message.find("no_such_trajectory"), std::string::npos);
}

TEST(ScanBadInput, NanSpeedScaleIsRefused) {
  actionlib::SimpleActionClient<cellsight::ScanAction> client("scan", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(30)));
  cellsight::ScanGoal goal;
  goal.poses.header.frame_id = "base_link";
  goal.poses.poses.resize(1);
  goal.poses.poses[0].orientation.w = 1;
  goal.continuous = true;
  goal.speed_scale = std::nan("");
  client.sendGoal(goal);
  ASSERT_TRUE(client.waitForResult(ros::Duration(20)));
  EXPECT_EQ(client.getResult()->status, cellsight::ScanResult::INVALID_GOAL);
  EXPECT_NE(client.getResult()->message.find("speed_scale"), std::string::npos) << client.getResult()->message;
}

// Requests name files, not paths: a path, a hidden name or another extension is refused before
// the robot moves; so is a later pass without its cycle or an unknown role.
TEST(ScanBadInput, OutputPathsAndPassesThatCannotBeAreRefused) {
  actionlib::SimpleActionClient<cellsight::ScanAction> client("scan", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(30)));
  const std::vector<std::pair<std::string, std::string>> bad{
      {"../outside.ply", "not a plain file name"}, {"/etc/cron.d/x.ply", "not a plain file name"},
      {".hidden.ply", "not a plain file name"}, {"scan.yaml", "must end in .ply, .pcd"}};
  for (const auto& [file, why] : bad) {
    cellsight::ScanGoal goal;
    goal.trajectory = "quick_sweep";
    goal.output_file = file;
    client.sendGoal(goal);
    ASSERT_TRUE(client.waitForResult(ros::Duration(20)));
    EXPECT_EQ(client.getResult()->status, cellsight::ScanResult::INVALID_GOAL) << file;
    EXPECT_NE(client.getResult()->message.find(why), std::string::npos) << client.getResult()->message;
  }
  cellsight::ScanGoal later;
  later.trajectory = "quick_sweep";
  later.role = cellsight::CyclePass::REFINE;
  client.sendGoal(later);
  ASSERT_TRUE(client.waitForResult(ros::Duration(20)));
  EXPECT_EQ(client.getResult()->status, cellsight::ScanResult::INVALID_GOAL);
  EXPECT_NE(client.getResult()->message.find("needs the cycle_id"), std::string::npos) << client.getResult()->message;
  later.cycle_id = "c";
  later.role = 7;
  client.sendGoal(later);
  ASSERT_TRUE(client.waitForResult(ros::Duration(20)));
  EXPECT_EQ(client.getResult()->status, cellsight::ScanResult::INVALID_GOAL);
  EXPECT_NE(client.getResult()->message.find("unknown role 7"), std::string::npos) << client.getResult()->message;
}

TEST(ScanBadInput, RobotThatNeverArrivesAbortsWithAClearStatus) {
  ros::NodeHandle nh;
  ros::ServiceServer robot = nh.advertiseService("robot/move_flange", stuckRobot);
  actionlib::SimpleActionClient<cellsight::ScanAction> client("scan", true);
  ASSERT_TRUE(client.waitForServer(ros::Duration(30)));
  cellsight::ScanGoal goal;
  goal.trajectory = "quick_sweep";
  client.sendGoal(goal);
  ASSERT_TRUE(client.waitForResult(ros::Duration(40)));
  EXPECT_EQ(client.getState(), actionlib::SimpleClientGoalState::ABORTED);
  EXPECT_EQ(client.getResult()->status, cellsight::ScanResult::ROBOT_TIMEOUT);
  EXPECT_NE(client.getResult()->message.find("io/in_position"), std::string::npos) << client.getResult()->message;
  // The server is still there for the next goal.
  client.sendGoal(goal);
  ASSERT_TRUE(client.waitForResult(ros::Duration(40)));
  EXPECT_EQ(client.getResult()->status, cellsight::ScanResult::ROBOT_TIMEOUT);
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_scan_bad_input");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
