// The model_matching node: the service refuses before any clusters and for an unknown model
// (and keeps answering); a cluster holding a single view of a part gives a detection, its tf
// frame and a correct pose; the scan's light sweep with the clusters' stamp is used, a missing or
// malformed one is named in the warnings; clusters in a frame with no transform are dropped, the
// node lives on; a cycle's passes are located together, a pass of another cycle or after the
// cycle's end is dropped.
#include <gtest/gtest.h>

#include <map>
#include <ros/package.h>
#include <ros/ros.h>
#include <ros/topic.h>
#include <diagnostic_msgs/DiagnosticArray.h>
#include <dynamic_reconfigure/Reconfigure.h>
#include <tf2_eigen/tf2_eigen.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <tf2_ros/transform_listener.h>

#include "cellsight/ClusterArray.h"
#include "cellsight/CyclePass.h"
#include "cellsight/DetectionArray.h"
#include "cellsight/LaserSweep.h"
#include "cellsight/LocateObjects.h"
#include "cellsight/localization/localization_eval.hpp"
#include "cellsight/localization/model_matching.hpp"
#include "cellsight_ros/conversions.hpp"

namespace {

cellsight::DetectionArrayConstPtr waitForDetections(const ros::Time& stamp, double seconds) {
  cellsight::DetectionArrayConstPtr got;
  ros::NodeHandle nh;
  auto sub = nh.subscribe<cellsight::DetectionArray>("detections", 1, [&](const cellsight::DetectionArrayConstPtr& m) {
    if (m->header.stamp == stamp) got = m;
  });
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(seconds);
  while (!got && ros::WallTime::now() < end) {
    ros::spinOnce();
    ros::WallDuration(0.05).sleep();
  }
  return got;
}

}  // namespace

TEST(ModelMatchingNode, ServiceClustersTfAndBadInput) {
  ros::NodeHandle nh;
  tf2_ros::Buffer buffer;
  tf2_ros::TransformListener listener(buffer);  // before the detections: object/<n> is not latched
  auto locate = nh.serviceClient<cellsight::LocateObjects>("model_matching/locate_objects");
  ASSERT_TRUE(locate.waitForExistence(ros::Duration(90)));
  cellsight::LocateObjects srv;
  ASSERT_TRUE(locate.call(srv));
  EXPECT_EQ(srv.response.status, cellsight::LocateObjects::Response::NO_CLUSTERS);
  EXPECT_NE(srv.response.message.find("no clusters"), std::string::npos) << srv.response.message;

  // the scanner camera of the demo cell, as calibration_publisher would send it
  tf2_ros::StaticTransformBroadcaster static_tf;
  Eigen::Isometry3d T_base_camera = Eigen::Isometry3d::Identity();
  T_base_camera.translation() = Eigen::Vector3d(0.52, 0, 0.62);
  T_base_camera.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();
  geometry_msgs::TransformStamped cam = tf2::eigenToTransform(T_base_camera);
  cam.header.frame_id = "base_link";
  cam.header.stamp = ros::Time::now();
  cam.child_frame_id = "scanner_camera_optical";
  static_tf.sendTransform(cam);

  const std::string models = ros::package::getPath("cellsight") + "/config/models";
  const cellsight::ModelLibrary lib(models);
  Eigen::Isometry3d truth = Eigen::Isometry3d::Identity();
  truth.translation() = Eigen::Vector3d(0.47, 0.03, 0);
  truth.linear() = Eigen::AngleAxisd(0.9, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  const cellsight::ScanCloud view =
      cellsight::singleViewCloud(lib.model("bracket").mesh, truth, Eigen::Vector3f(0.52f, 0.f, 0.62f), 0.001, 2e-5, 11);
  cellsight::ClusterArray clusters;
  clusters.header.frame_id = "base_link";
  clusters.header.stamp = ros::Time::now();
  clusters.clusters.emplace_back();
  clusters.clusters.back().cloud = cellsight_ros::toCloudMsg(view, clusters.header.stamp);
  clusters.clusters.back().cloud.header.frame_id = "base_link";
  cellsight::ScanCloud nan;
  for (int i = 0; i < 20; ++i) nan.append(Eigen::Vector3f::Constant(NAN), 0.f);
  clusters.clusters.emplace_back();
  clusters.clusters.back().cloud = cellsight_ros::toCloudMsg(nan, clusters.header.stamp);
  auto pub = nh.advertise<cellsight::ClusterArray>("clusters", 1, true);
  ros::WallDuration(1.0).sleep();
  pub.publish(clusters);
  const auto det = waitForDetections(clusters.header.stamp, 60);
  ASSERT_TRUE(det) << "no detections for the published clusters";
  ASSERT_EQ(det->detections.size(), 1u);
  EXPECT_EQ(det->detections[0].model, "bracket");
  Eigen::Isometry3d pose;
  tf2::fromMsg(det->detections[0].pose, pose);
  cellsight::ModelMatcher centroid(std::make_shared<const cellsight::ModelLibrary>(models), cellsight::MatchingConfig());
  const auto e = cellsight::poseError(lib.model("bracket").info, centroid.centroid("bracket"), pose, truth);
  EXPECT_LT(e.translation, 1e-3);
  EXPECT_LT(e.rotation, 1 * M_PI / 180);
  EXPECT_FALSE(det->warnings.empty());  // the all-NaN cluster is named
  auto warned = [](const cellsight::DetectionArray& d, const std::string& what) {
    for (const auto& w : d.warnings)
      if (w.find(what) != std::string::npos) return true;
    return false;
  };
  EXPECT_TRUE(warned(*det, "light_sweep with the clusters' stamp")) << "no sweep was published";

  EXPECT_EQ(det->detections[0].name, "object/bracket_0");
  EXPECT_TRUE(buffer.canTransform("base_link", "object/bracket_0", clusters.header.stamp, ros::Duration(5)));
  // re-published: the frame is still there, at a later time, with nothing new scanned
  ros::WallDuration(1.0).sleep();
  EXPECT_TRUE(buffer.canTransform("base_link", "object/bracket_0", ros::Time(0), ros::Duration(2)));
  EXPECT_GT(buffer.lookupTransform("base_link", "object/bracket_0", ros::Time(0)).header.stamp, clusters.header.stamp);

  srv.request.models = {"no_such_part"};
  ASSERT_TRUE(locate.call(srv));
  EXPECT_EQ(srv.response.status, cellsight::LocateObjects::Response::UNKNOWN_MODEL);
  EXPECT_NE(srv.response.message.find("unknown model 'no_such_part'"), std::string::npos) << srv.response.message;
  srv.request.models = {"bracket"};
  ASSERT_TRUE(locate.call(srv));
  EXPECT_EQ(srv.response.status, cellsight::LocateObjects::Response::OK) << srv.response.message;
  EXPECT_EQ(srv.response.detections.detections.size(), 1u);

  // dynamic_reconfigure: a 10 um RMSE limit rejects the (20 um noise) view, the shipped one accepts it again
  auto reconfigure = nh.serviceClient<dynamic_reconfigure::Reconfigure>("model_matching/set_parameters");
  ASSERT_TRUE(reconfigure.waitForExistence(ros::Duration(10)));
  dynamic_reconfigure::Reconfigure rc;
  dynamic_reconfigure::DoubleParameter rmse;
  rmse.name = "max_rmse";
  rmse.value = 1e-5;
  rc.request.config.doubles.push_back(rmse);
  ASSERT_TRUE(reconfigure.call(rc));
  ASSERT_TRUE(locate.call(srv));
  EXPECT_EQ(srv.response.status, cellsight::LocateObjects::Response::OK) << srv.response.message;
  EXPECT_EQ(srv.response.detections.detections.size(), 0u) << "max_rmse 10 um should reject the view";
  rc.request.config.doubles[0].value = 0.0015;
  ASSERT_TRUE(reconfigure.call(rc));
  ASSERT_TRUE(locate.call(srv));
  EXPECT_EQ(srv.response.detections.detections.size(), 1u);

  // the scan's light sweep with the clusters' stamp is used (no warning, the part still found);
  // a malformed one is named and the fitness counts every visible point
  auto sweep_pub = nh.advertise<cellsight::LaserSweep>("scan/light_sweep", 1, true);
  cellsight::LightSweep sheet;
  for (int k = 0; k <= 100; ++k) sheet.add({0.40f + 0.002f * k, -0.1f, 0.45f}, Eigen::Vector3f::UnitX(), -(0.40f + 0.002f * k));
  for (const bool good : {true, false}) {
    clusters.header.stamp = ros::Time::now();
    cellsight::LaserSweep sm = cellsight_ros::toLaserSweepMsg(sheet, "base_link", clusters.header.stamp);
    if (!good) sm.offsets.pop_back();
    sweep_pub.publish(sm);
    ros::WallDuration(0.5).sleep();
    pub.publish(clusters);
    const auto lit = waitForDetections(clusters.header.stamp, 60);
    ASSERT_TRUE(lit) << "no detections for the clusters with a sweep";
    EXPECT_EQ(lit->detections.size(), 1u);
    EXPECT_FALSE(warned(*lit, "light_sweep with the clusters' stamp"));
    EXPECT_EQ(warned(*lit, "unusable"), !good);
  }

  // no transform for this frame: dropped (no detections for this stamp), the node keeps serving
  clusters.header.frame_id = "nowhere";
  clusters.header.stamp = ros::Time::now();
  pub.publish(clusters);
  EXPECT_FALSE(waitForDetections(clusters.header.stamp, 5));
  // the service locates the latest cycle again: the dropped scan is not in it
  srv.request.models = {};
  ASSERT_TRUE(locate.call(srv));
  EXPECT_EQ(srv.response.status, cellsight::LocateObjects::Response::OK) << srv.response.message;
  EXPECT_EQ(srv.response.detections.detections.size(), 1u);

  // a cycle of passes (cellsight/CyclePass on scan/pass, the clusters' stamp): a detect pass, a
  // pass of another cycle dropped, the refine pass that ends the cycle, a pass after its end dropped
  clusters.header.frame_id = "base_link";
  auto pass_pub = nh.advertise<cellsight::CyclePass>("scan/pass", 4, true);
  auto send_pass = [&](const std::string& cycle, uint8_t role, bool last, uint64_t seed) {
    clusters.header.stamp = ros::Time::now();
    clusters.clusters.resize(1);
    clusters.clusters[0].cloud = cellsight_ros::toCloudMsg(
        cellsight::singleViewCloud(lib.model("bracket").mesh, truth, Eigen::Vector3f(0.52f, 0.f, 0.62f), 0.001, 2e-5, seed),
        clusters.header.stamp);
    clusters.clusters[0].cloud.header.frame_id = "base_link";
    cellsight::CyclePass p;
    p.header = clusters.header;
    p.cycle_id = cycle;
    p.role = role;
    p.last = last;
    pass_pub.publish(p);
    ros::WallDuration(0.5).sleep();
    pub.publish(clusters);
    return waitForDetections(clusters.header.stamp, role == cellsight::CyclePass::DETECT || cycle == "c1" ? 60 : 5);
  };
  const auto first = send_pass("c1", cellsight::CyclePass::DETECT, false, 21);
  ASSERT_TRUE(first) << "no detections for the cycle's detect pass";
  EXPECT_EQ(first->cycle_id, "c1");
  EXPECT_EQ(first->passes, std::vector<uint8_t>{cellsight::CyclePass::DETECT});
  EXPECT_FALSE(first->final);
  ASSERT_EQ(first->detections.size(), 1u);
  EXPECT_FALSE(send_pass("c2", cellsight::CyclePass::REFINE, true, 22)) << "a pass of another cycle was located";
  const auto last = send_pass("c1", cellsight::CyclePass::REFINE, true, 23);
  ASSERT_TRUE(last) << "no detections for the cycle's refine pass";
  EXPECT_EQ(last->passes, (std::vector<uint8_t>{cellsight::CyclePass::DETECT, cellsight::CyclePass::REFINE}));
  EXPECT_TRUE(last->final);
  ASSERT_EQ(last->detections.size(), 1u);
  EXPECT_EQ(last->detections[0].name, first->detections[0].name);  // the same part keeps its name
  EXPECT_FALSE(send_pass("c1", cellsight::CyclePass::ADD_DETECTIONS, false, 24)) << "a pass after the cycle's end was located";
  // diagnostics: the node reports the scans it processed and the one it dropped, with the reason
  std::map<std::string, std::string> kv;
  for (int tries = 0; tries < 10 && (kv["dropped: no scanner camera transform at the scan's stamp"] != "1" ||
                                     kv["dropped: a pass outside its cycle"] != "2"); ++tries) {
    const auto diag = ros::topic::waitForMessage<diagnostic_msgs::DiagnosticArray>("/diagnostics", nh, ros::Duration(3));
    ASSERT_TRUE(diag) << "no /diagnostics";
    for (const auto& st : diag->status) {
      if (st.name.find("model_matching") == std::string::npos) continue;
      kv.clear();
      for (const auto& v : st.values) kv[v.key] = v.value;
    }
  }
  EXPECT_EQ(kv["dropped: no scanner camera transform at the scan's stamp"], "1");
  EXPECT_EQ(kv["dropped: a pass outside its cycle"], "2");
  ASSERT_FALSE(kv["scans processed"].empty());
  EXPECT_GE(std::stoi(kv["scans processed"]), 5);
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_model_matching_node");
  return RUN_ALL_TESTS();
}
