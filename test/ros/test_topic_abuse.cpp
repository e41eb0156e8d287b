// Topic abuse: the malformed messages of docs/reliability.md (size fields that overflow, a zero
// point step under a huge width, field offsets past the point, NaN-only and empty clouds, images
// whose step × height wraps in 32 bits, camera_infos of 60000² or with NaN / zero focal length)
// are published, many times each, into every node that takes them from outside. Afterwards each
// node is the same process, still answers (a valid message or service call gets its answer) and
// its resident memory grew by less than kMaxGrowthKb.
#include <gtest/gtest.h>
#include <ros/network.h>
#include <ros/ros.h>
#include <sensor_msgs/CameraInfo.h>
#include <sensor_msgs/Image.h>
#include <sensor_msgs/PointCloud2.h>
#include <sensor_msgs/point_cloud2_iterator.h>
#include <std_srvs/Trigger.h>
#include <tf2_ros/static_transform_broadcaster.h>
#include <xmlrpcpp/XmlRpc.h>

#include <array>
#include <cmath>
#include <cstring>
#include <fstream>
#include <functional>
#include <limits>
#include <map>
#include <string>
#include <vector>

#include "cellsight/CalibrateIntrinsics.h"
#include "cellsight/ClusterArray.h"
#include "cellsight/LaserPlaneStamped.h"
#include "cellsight/LocateObjects.h"

namespace {

constexpr long kMaxGrowthKb = 64 * 1024;  // per node, over the whole abuse
constexpr int kRepeats = 10;              // each malformed message is sent this many times
const std::vector<std::string> kNodes = {"clustering", "model_matching", "triangulation", "laser_plane_tracker",
                                         "scanner_calibration"};

/// The node's process id through its XML-RPC API (getPid), 0 when it does not answer.
int pidOf(const std::string& node) {
  XmlRpc::XmlRpcValue args, result, payload;
  args[0] = ros::this_node::getName();
  args[1] = "/" + node;
  if (!ros::master::execute("lookupNode", args, result, payload, false)) return 0;
  std::string host;
  uint32_t port = 0;
  if (!ros::network::splitURI(static_cast<std::string>(payload), host, port)) return 0;
  XmlRpc::XmlRpcClient client(host.c_str(), static_cast<int>(port), "/");
  XmlRpc::XmlRpcValue pid_args, pid_result;
  pid_args[0] = ros::this_node::getName();
  if (!client.execute("getPid", pid_args, pid_result) || pid_result.getType() != XmlRpc::XmlRpcValue::TypeArray ||
      pid_result.size() != 3 || static_cast<int>(pid_result[0]) != 1)
    return 0;
  return static_cast<int>(pid_result[2]);
}

/// VmRSS of a process in kB (-1 when it is gone).
long rssKb(int pid) {
  std::ifstream in("/proc/" + std::to_string(pid) + "/status");
  std::string key;
  while (in >> key) {
    if (key == "VmRSS:") {
      long kb = -1;
      in >> kb;
      return kb;
    }
    std::getline(in, key);
  }
  return -1;
}

sensor_msgs::PointField field(const std::string& name, uint32_t offset, uint8_t type = sensor_msgs::PointField::FLOAT32) {
  sensor_msgs::PointField f;
  f.name = name;
  f.offset = offset;
  f.datatype = type;
  f.count = 1;
  return f;
}

sensor_msgs::PointCloud2 xyzCloud(const std::vector<std::array<float, 3>>& points, const ros::Time& stamp) {
  sensor_msgs::PointCloud2 m;
  m.header.frame_id = "base_link";
  m.header.stamp = stamp;
  m.height = 1;
  m.width = static_cast<uint32_t>(points.size());
  m.fields = {field("x", 0), field("y", 4), field("z", 8)};
  m.point_step = 12;
  m.row_step = m.width * m.point_step;
  m.is_dense = false;
  m.data.resize(m.row_step);
  for (size_t i = 0; i < points.size(); ++i) std::memcpy(&m.data[i * 12], points[i].data(), 12);
  return m;
}

/// The class-1 clouds: each one a reason for fromCloudMsg to refuse.
std::vector<sensor_msgs::PointCloud2> badClouds() {
  std::vector<sensor_msgs::PointCloud2> out;
  const ros::Time t = ros::Time::now();
  sensor_msgs::PointCloud2 m = xyzCloud({{0.f, 0.f, 0.f}}, t);
  m.width = 0x40000000u;  // width × point_step overflows uint32 (row_step wraps to 0)
  m.point_step = 16;
  m.row_step = m.width * m.point_step;
  out.push_back(m);
  m = xyzCloud({}, t);
  m.width = 0xFFFFFFF0u;  // zero point step under a huge width: nothing to read, ~4 GB to allocate
  m.point_step = 0;
  m.row_step = 0;
  out.push_back(m);
  m = xyzCloud({{0.f, 0.f, 0.f}, {1.f, 1.f, 1.f}}, t);
  m.fields = {field("x", 0), field("y", 4), field("z", 100), field("intensity", 200)};  // past point_step
  out.push_back(m);
  m = xyzCloud({{0.f, 0.f, 0.f}}, t);
  m.width = 1000;  // data shorter than the layout claims
  m.row_step = 12000;
  out.push_back(m);
  const float nan = std::numeric_limits<float>::quiet_NaN();
  out.push_back(xyzCloud(std::vector<std::array<float, 3>>(50, {nan, nan, nan}), t));  // NaN only
  out.push_back(xyzCloud({}, t));                                                       // empty
  m = xyzCloud({{0.f, 0.f, 0.f}}, t);
  m.fields.clear();  // no fields
  out.push_back(m);
  m = xyzCloud({{0.f, 0.f, 0.f}}, t);
  m.fields = {field("x", 0, 42), field("y", 4), field("z", 8)};  // unknown datatype
  out.push_back(m);
  return out;
}

sensor_msgs::CameraInfo cameraInfo(uint32_t w, uint32_t h, double f, const ros::Time& stamp) {
  sensor_msgs::CameraInfo c;
  c.header.frame_id = "scanner_camera_optical";
  c.header.stamp = stamp;
  c.width = w;
  c.height = h;
  c.distortion_model = "plumb_bob";
  c.D = {0, 0, 0, 0, 0};
  c.K = {f, 0, w / 2.0, 0, f, h / 2.0, 0, 0, 1};
  c.R = {1, 0, 0, 0, 1, 0, 0, 0, 1};
  c.P = {f, 0, w / 2.0, 0, 0, f, h / 2.0, 0, 0, 0, 1, 0};
  return c;
}

std::vector<sensor_msgs::CameraInfo> badCameraInfos() {
  const ros::Time t = ros::Time::now();
  std::vector<sensor_msgs::CameraInfo> out;
  out.push_back(cameraInfo(60000, 60000, 5000, t));  // an undistortion map of 3.6 G pixels
  out.push_back(cameraInfo(64, 48, 0, t));           // zero focal length
  sensor_msgs::CameraInfo c = cameraInfo(64, 48, 50, t);
  c.K[2] = std::nan("");
  out.push_back(c);
  c = cameraInfo(64, 48, 50, t);
  c.D = {0.1, 0.2, 0.3};  // plumb_bob with 3 terms
  out.push_back(c);
  c = cameraInfo(64, 48, 50, t);
  c.distortion_model = "no_such_model";
  out.push_back(c);
  out.push_back(cameraInfo(0, 0, 50, t));
  return out;
}

/// Images of the size of cameraInfo(64, 48, ...) that the conversion must refuse.
std::vector<sensor_msgs::Image> badImages(const ros::Time& stamp) {
  sensor_msgs::Image im;
  im.header.frame_id = "scanner_camera_optical";
  im.header.stamp = stamp;
  im.width = 64;
  im.height = 48;
  im.encoding = "mono8";
  std::vector<sensor_msgs::Image> out;
  im.step = 268435456u;  // 48 × step = 3 × 2^32: wraps to 0 in 32 bits, data empty
  out.push_back(im);
  im.step = 89478486u;  // 48 × step = 2^32 + 32: 32 bytes pass a 32-bit check (cv_bridge's), rows 4 GB apart
  im.data.assign(32, 0);
  out.push_back(im);
  im.step = 10;  // less than width
  im.data.assign(480, 0);
  out.push_back(im);
  im.step = 64;  // data short of step × height
  im.data.assign(100, 0);
  out.push_back(im);
  im.encoding = "rgb8";  // step of a mono image under a colour encoding
  im.data.assign(64 * 48, 0);
  out.push_back(im);
  im.encoding = "32FC1";
  out.push_back(im);
  return out;
}

template <class M>
void publishAll(ros::Publisher& pub, const std::vector<M>& messages) {
  for (int r = 0; r < kRepeats; ++r) {
    for (const M& m : messages) {
      pub.publish(m);
      ros::WallDuration(0.01).sleep();
    }
  }
}

void waitForSubscriber(const ros::Publisher& pub, const std::string& what) {
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(60);
  while (pub.getNumSubscribers() == 0 && ros::WallTime::now() < end) ros::WallDuration(0.05).sleep();
  ASSERT_GT(pub.getNumSubscribers(), 0u) << "nobody subscribes to " << what;
}

}  // namespace

TEST(TopicAbuse, EveryNodeLivesServesAndKeepsItsMemory) {
  ros::NodeHandle nh;
  // every node is up: its process id and its memory before
  std::map<std::string, int> pid;
  std::map<std::string, long> rss_before;
  ASSERT_TRUE(ros::service::waitForService("model_matching/locate_objects", ros::Duration(120)));
  ASSERT_TRUE(ros::service::waitForService("scanner_calibration/intrinsics", ros::Duration(60)));
  ASSERT_TRUE(ros::service::waitForService("scan/reset", ros::Duration(60)));
  for (const auto& n : kNodes) {
    const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(60);
    while ((pid[n] = pidOf(n)) == 0 && ros::WallTime::now() < end) ros::WallDuration(0.2).sleep();
    ASSERT_GT(pid[n], 0) << n << " is not running";
    rss_before[n] = rssKb(pid[n]);
    ASSERT_GT(rss_before[n], 0) << n;
  }

  // the camera above the table (model_matching needs its pose to take clusters) and the laser on
  // the camera (laser_plane_tracker)
  tf2_ros::StaticTransformBroadcaster static_tf;
  geometry_msgs::TransformStamped camera, laser;
  camera.header.frame_id = "base_link";
  camera.header.stamp = ros::Time::now();
  camera.child_frame_id = "scanner_camera_optical";
  camera.transform.translation.z = 0.6;
  camera.transform.rotation.x = 1;  // looking down
  laser.header = camera.header;
  laser.header.frame_id = "scanner_camera_optical";
  laser.child_frame_id = "laser";
  laser.transform.translation.x = 0.1;
  laser.transform.rotation.w = 1;
  static_tf.sendTransform(std::vector<geometry_msgs::TransformStamped>{camera, laser});
  ros::WallDuration(0.5).sleep();

  ros::Publisher cloud_pub = nh.advertise<sensor_msgs::PointCloud2>("scan/cloud", 10);
  ros::Publisher clusters_pub = nh.advertise<cellsight::ClusterArray>("clusters", 10);
  ros::Publisher info_pub = nh.advertise<sensor_msgs::CameraInfo>("scanner_camera/camera_info", 10);
  ros::Publisher image_pub = nh.advertise<sensor_msgs::Image>("scanner_camera/image_raw", 10);
  ros::Publisher plane_pub = nh.advertise<cellsight::LaserPlaneStamped>("scan/laser_plane", 10);
  waitForSubscriber(cloud_pub, "scan/cloud");
  waitForSubscriber(clusters_pub, "clusters");
  waitForSubscriber(info_pub, "scanner_camera/camera_info");
  waitForSubscriber(image_pub, "scanner_camera/image_raw");
  waitForSubscriber(plane_pub, "scan/laser_plane");

  // clustering and model_matching: the bad clouds, alone and inside a cluster array
  const std::vector<sensor_msgs::PointCloud2> clouds = badClouds();
  publishAll(cloud_pub, clouds);
  cellsight::ClusterArray arr;
  arr.header.frame_id = "base_link";
  arr.header.stamp = ros::Time::now();
  for (const auto& c : clouds) {
    cellsight::Cluster cl;
    cl.cloud = c;
    arr.clusters.push_back(cl);
  }
  publishAll(clusters_pub, std::vector<cellsight::ClusterArray>{arr});
  // a readable cluster on the table with one point 1e8 m away: the matcher cannot grid it, and
  // the node must say so and go on, not die
  std::vector<std::array<float, 3>> far;
  for (int i = 0; i < 20; ++i)
    for (int j = 0; j < 20; ++j) far.push_back({0.5f + 0.001f * i, 0.001f * j, 0.01f});
  far.push_back({1e8f, 0.f, 0.f});
  cellsight::ClusterArray far_arr;
  far_arr.header = arr.header;
  far_arr.clusters.emplace_back();
  far_arr.clusters.back().cloud = xyzCloud(far, arr.header.stamp);
  publishAll(clusters_pub, std::vector<cellsight::ClusterArray>{far_arr});

  // triangulation and laser_plane_tracker: the bad camera_infos, then a good one and bad images
  // paired with a laser plane of the same stamp (so each reaches the image conversion)
  publishAll(info_pub, badCameraInfos());
  info_pub.publish(cameraInfo(64, 48, 50, ros::Time::now()));
  ros::WallDuration(0.5).sleep();
  for (int r = 0; r < kRepeats; ++r) {
    ros::Time stamp = ros::Time::now();
    for (auto im : badImages(stamp)) {
      stamp += ros::Duration(1e-6);  // one stamp per image, and its plane
      im.header.stamp = stamp;
      cellsight::LaserPlaneStamped plane;
      plane.header.frame_id = "scanner_camera_optical";
      plane.header.stamp = stamp;
      plane.normal.y = 1;
      plane.d = -0.1;
      image_pub.publish(im);
      plane_pub.publish(plane);
      ros::WallDuration(0.01).sleep();
    }
  }

  // scanner_calibration: the bad images inside service requests
  auto intrinsics = nh.serviceClient<cellsight::CalibrateIntrinsics>("scanner_calibration/intrinsics");
  for (const auto& im : badImages(ros::Time::now())) {
    cellsight::CalibrateIntrinsics srv;
    srv.request.images = {im, im, im};
    srv.request.board_cols = 9;
    srv.request.board_rows = 6;
    srv.request.square_size = 0.025;
    ASSERT_TRUE(intrinsics.call(srv)) << "scanner_calibration did not answer";
    EXPECT_EQ(srv.response.status, cellsight::CalibrateIntrinsics::Response::FAILED);
    EXPECT_NE(srv.response.message.find("image"), std::string::npos) << srv.response.message;
  }
  ros::WallDuration(1.0).sleep();

  // each node: the same process, memory within the bound
  for (const auto& n : kNodes) {
    EXPECT_EQ(pidOf(n), pid[n]) << n << " died or was restarted";
    const long after = rssKb(pid[n]);
    ASSERT_GT(after, 0) << n << " is gone";
    EXPECT_LT(after - rss_before[n], kMaxGrowthKb) << n << ": " << rss_before[n] << " kB before, " << after << " kB after";
    std::printf("topic_abuse: %s RSS %ld kB before, %ld kB after\n", n.c_str(), rss_before[n], after);
  }

  // ... and each still serves: a valid cloud gets its clusters, the services answer, a valid
  // camera_info gets its laser plane
  cellsight::ClusterArrayConstPtr clusters;
  auto sub = nh.subscribe<cellsight::ClusterArray>("clusters", 5, [&](const cellsight::ClusterArrayConstPtr& m) {
    if (m->input_points == 2500) clusters = m;
  });
  std::vector<std::array<float, 3>> pts;
  for (int i = 0; i < 50; ++i)
    for (int j = 0; j < 50; ++j) pts.push_back({0.3f + 0.004f * i, -0.1f + 0.004f * j, 0.f});
  const ros::WallTime end = ros::WallTime::now() + ros::WallDuration(30);
  while (!clusters && ros::WallTime::now() < end) {
    cloud_pub.publish(xyzCloud(pts, ros::Time::now()));
    ros::WallDuration(0.5).sleep();
  }
  EXPECT_TRUE(clusters) << "clustering no longer answers a valid cloud";

  cellsight::LaserPlaneStampedConstPtr plane;
  auto plane_sub = nh.subscribe<cellsight::LaserPlaneStamped>("scan/laser_plane", 5,
                                                             [&](const cellsight::LaserPlaneStampedConstPtr& m) { plane = m; });
  const ros::WallTime end2 = ros::WallTime::now() + ros::WallDuration(30);
  while (!plane && ros::WallTime::now() < end2) {
    info_pub.publish(cameraInfo(64, 48, 50, ros::Time::now()));
    ros::WallDuration(0.5).sleep();
  }
  EXPECT_TRUE(plane) << "laser_plane_tracker no longer answers a valid camera_info";

  std_srvs::Trigger reset;
  EXPECT_TRUE(ros::service::call("scan/reset", reset)) << "triangulation no longer answers scan/reset";
  cellsight::LocateObjects locate;
  EXPECT_TRUE(ros::service::call("model_matching/locate_objects", locate)) << "model_matching no longer answers";
  cellsight::CalibrateIntrinsics empty;
  EXPECT_TRUE(ros::service::call("scanner_calibration/intrinsics", empty)) << "scanner_calibration no longer answers";
  EXPECT_EQ(empty.response.status, cellsight::CalibrateIntrinsics::Response::FAILED);
}

int main(int argc, char** argv) {
  testing::InitGoogleTest(&argc, argv);
  ros::init(argc, argv, "test_topic_abuse");
  ros::AsyncSpinner spinner(2);
  spinner.start();
  return RUN_ALL_TESTS();
}
