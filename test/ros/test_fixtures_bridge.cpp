// qr_frame_adjustment and robot_bridge as a cell runs them: images without their camera pose in
// tf are dropped (NO_TRANSFORM), then every demo fixture is found and its UCS reaches tf and the
// robot over TCP; teaching stores a UCS; a wrong image encoding leaves the node serving; the
// stop-and-go handshake answers CAPTURED, or ERR CAPTURE when nobody captures.
#include <gtest/gtest.h>

#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <std_msgs/Bool.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>

#include <atomic>
#include <filesystem>
#include <mutex>
#include <thread>

#include "cellsight/AdjustFixtures.h"
#include "cellsight/TeachFixture.h"
#include "cellsight/bridge/line_client.hpp"
#include "cellsight/eval/fixture_eval.hpp"
#include "cellsight/sim/renderer.hpp"
#include "cellsight_ros/conversions.hpp"

namespace {

const std::string kRoot = CELLSIGHT_SOURCE_DIR;

}  // namespace

TEST(FixturesAndBridge, TheCellAsARobotSeesIt) {
  ros::NodeHandle nh;
  ros::AsyncSpinner spinner(2);
  spinner.start();
  const cellsight::Scene scene = cellsight::loadScene(kRoot + "/config/scenes/demo.yaml");
  const cellsight::FixtureRegistry registry = cellsight::loadFixtureRegistry(kRoot + "/config/fixtures.yaml");
  const cv::Mat image = cellsight::FixtureRenderer(std::make_shared<cellsight::CellGeometry>(scene)).render(5);
  const auto& cam = scene.fixture_camera;
  auto image_pub = nh.advertise<sensor_msgs::Image>("fixture_camera/image_raw", 2);
  auto info_pub = nh.advertise<sensor_msgs::CameraInfo>("fixture_camera/camera_info", 2);
  std::atomic<bool> bad_encoding{false}, running{true};
  std::thread camera([&] {
    ros::WallRate rate(5.0);
    while (running && ros::ok()) {
      const ros::Time stamp = ros::Time::now();
      sensor_msgs::Image img = cellsight_ros::toImageMsg(image, cam.frame_id, stamp);
      if (bad_encoding) img.encoding = "16UC1";
      image_pub.publish(img);
      info_pub.publish(cellsight_ros::toCameraInfo(cam.intrinsics, cam.frame_id, stamp));
      rate.sleep();
    }
  });
  auto adjust = nh.serviceClient<cellsight::AdjustFixtures>("qr_frame_adjustment/adjust");
  ASSERT_TRUE(adjust.waitForExistence(ros::Duration(60)));
  cellsight::AdjustFixtures srv;
  srv.request.timeout = 5.0;
  ASSERT_TRUE(adjust.call(srv));
  EXPECT_EQ(srv.response.status, cellsight::AdjustFixtures::Response::NO_TRANSFORM) << srv.response.message;

  // the camera's pose in tf: every fixture, its UCS within 0.1 mm of the truth
  tf2_ros::StaticTransformBroadcaster static_tf;
  geometry_msgs::TransformStamped t = tf2::eigenToTransform(cam.T_base_camera);
  t.header.frame_id = "base_link";
  t.child_frame_id = cam.frame_id;
  t.header.stamp = ros::Time(0);
  static_tf.sendTransform(t);
  bool ok = false;
  for (int i = 0; i < 20 && !ok; ++i) {
    ASSERT_TRUE(adjust.call(srv));
    ok = srv.response.status == cellsight::AdjustFixtures::Response::OK && srv.response.fixtures.size() == 3;
  }
  ASSERT_TRUE(ok) << srv.response.message;
  EXPECT_EQ(srv.response.program, "weld_a");
  const auto truth = cellsight::fixtureTruth(scene, registry);
  for (const auto& f : srv.response.fixtures) {
    const auto it = std::find_if(truth.begin(), truth.end(), [&](const cellsight::FixtureTruth& x) { return x.type == f.type; });
    ASSERT_NE(it, truth.end());
    EXPECT_LT(cellsight::poseDifference(cellsight_ros::fromPoseMsg(f.ucs), it->T_base_ucs).first, 0.1e-3) << f.id;
    EXPECT_FALSE(f.stale);
  }
  tf2_ros::Buffer buffer;
  tf2_ros::TransformListener listener(buffer);
  EXPECT_TRUE(buffer.canTransform("base_link", "ucs/pick_c", ros::Time(0), ros::Duration(3.0)));
  EXPECT_TRUE(buffer.canTransform("base_link", "fixture/B", ros::Time(0), ros::Duration(3.0)));

  // four clients asking at once with long timeouts: images go on being processed on their own
  // thread, two requests wait and are answered with the next image, the others are told BUSY at once
  {
    std::vector<uint8_t> statuses(4, 255);
    std::vector<std::thread> clients;
    const ros::WallTime t0 = ros::WallTime::now();
    for (size_t i = 0; i < statuses.size(); ++i)
      clients.emplace_back([&, i] {
        ros::ServiceClient c = nh.serviceClient<cellsight::AdjustFixtures>("qr_frame_adjustment/adjust");
        cellsight::AdjustFixtures s;
        s.request.timeout = 60;  // clamped to 10 s
        if (c.call(s)) statuses[i] = s.response.status;
      });
    for (auto& t : clients) t.join();
    EXPECT_LT((ros::WallTime::now() - t0).toSec(), 8.0) << "the waiting requests starved the images";
    int ok = 0;
    for (const uint8_t st : statuses) {
      EXPECT_TRUE(st == cellsight::AdjustFixtures::Response::OK || st == cellsight::AdjustFixtures::Response::BUSY) << int(st);
      ok += st == cellsight::AdjustFixtures::Response::OK;
    }
    EXPECT_GE(ok, 2);
  }

  // teaching: an unknown type is refused; a known one is stored in the teach file
  auto teach = nh.serviceClient<cellsight::TeachFixture>("qr_frame_adjustment/teach");
  cellsight::TeachFixture tr;
  tr.request.type = "Z";
  ASSERT_TRUE(teach.call(tr));
  EXPECT_FALSE(tr.response.success);
  std::string taught_file;  // a new name per run (fixtures_bridge.test): no earlier run's teach is loaded
  ASSERT_TRUE(nh.getParam("qr_frame_adjustment/teach_file", taught_file));
  Eigen::Isometry3d ucs = truth.front().T_base_fixture * Eigen::Translation3d(0.01, 0.02, 0.0);
  tr.request.type = truth.front().type;
  tr.request.ucs = cellsight_ros::toPoseMsg(ucs);
  ASSERT_TRUE(teach.call(tr));
  EXPECT_TRUE(tr.response.success) << tr.response.message;
  const cellsight::FixtureRegistry taught = cellsight::loadFixtureRegistry(taught_file);
  const auto* type = std::find_if(taught.fixtures.begin(), taught.fixtures.end(),
                                  [&](const cellsight::FixtureType& f) { return f.type == truth.front().type; }).base();
  EXPECT_LT((type->T_fixture_ucs.translation() - Eigen::Vector3d(0.01, 0.02, 0.0)).norm(), 0.2e-3);
  EXPECT_FALSE(type->taught.empty());
  // a UCS far outside any cell is refused, the taught file kept; the node goes on detecting
  tr.request.ucs.position.x = 1e160;
  ASSERT_TRUE(teach.call(tr));
  EXPECT_FALSE(tr.response.success);
  EXPECT_NE(tr.response.message.find("within 2 m of its fixture"), std::string::npos) << tr.response.message;
  EXPECT_NO_THROW(cellsight::loadFixtureRegistry(taught_file));
  std::filesystem::remove(taught_file);
  cellsight::AdjustFixtures after;
  ASSERT_TRUE(adjust.call(after));
  EXPECT_EQ(after.response.status, cellsight::AdjustFixtures::Response::OK) << after.response.message;

  // the robot over TCP
  int port = 0;
  for (int i = 0; i < 100 && !nh.getParam("robot_bridge/bound_port", port); ++i) ros::WallDuration(0.1).sleep();
  ASSERT_GT(port, 0);
  cellsight::LineClient robot("127.0.0.1", port);
  EXPECT_EQ(robot.request("HELLO test_controller"), "OK HELLO cellsight kuka");
  const std::string a = robot.request("ADJUST");
  EXPECT_EQ(a.rfind("OK ADJUST A A weld_a ", 0), 0u) << a;
  const std::string u = robot.request("UCS pick_c");
  EXPECT_EQ(u.rfind("OK UCS pick_c ", 0), 0u) << u;
  EXPECT_NE(u.find("FRESH"), std::string::npos) << u;
  EXPECT_EQ(robot.request("UCS nobody").rfind("ERR UNKNOWN_PROGRAM", 0), 0u);
  std::atomic<bool> capture{true};
  auto done_pub = nh.advertise<std_msgs::Bool>("io/capture_done", 10);
  auto inpos_sub = nh.subscribe<std_msgs::Bool>("io/in_position", 10, [&](const std_msgs::BoolConstPtr& m) {
    if (!m->data || !capture) return;
    std_msgs::Bool d;
    d.data = true;
    done_pub.publish(d);
  });
  ros::WallDuration(1.0).sleep();  // connections
  EXPECT_EQ(robot.request("INPOS 1", 5.0), "OK CAPTURED 1");
  capture = false;
  EXPECT_EQ(robot.request("INPOS 2", 5.0).rfind("ERR CAPTURE 2", 0), 0u);

  // a wrong encoding: dropped, the node keeps serving (the last good fixtures kept, then stale)
  bad_encoding = true;
  ros::WallDuration(1.0).sleep();
  bad_encoding = false;
  ASSERT_TRUE(adjust.call(srv));
  EXPECT_EQ(srv.response.status, cellsight::AdjustFixtures::Response::OK) << srv.response.message;
  running = false;
  camera.join();
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_fixtures_bridge");
  return RUN_ALL_TESTS();
}
