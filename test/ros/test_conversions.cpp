#include <gtest/gtest.h>

#include <functional>
#include <limits>

#include "cellsight/localization/model_matching.hpp"
#include "cellsight_ros/conversions.hpp"

using namespace cellsight_ros;

TEST(Conversions, PoseAndTransformRoundTrip) {
  const Eigen::Isometry3d T = Eigen::Translation3d(0.1, -0.2, 0.3) *
                              Eigen::AngleAxisd(0.7, Eigen::Vector3d(1, -2, 0.5).normalized());
  EXPECT_TRUE(fromPoseMsg(toPoseMsg(T)).isApprox(T, 1e-12));
  EXPECT_TRUE(fromTransformMsg(toTransformMsg(T)).isApprox(T, 1e-12));
  geometry_msgs::Pose bad;
  EXPECT_THROW(fromPoseMsg(bad), std::invalid_argument);  // zero quaternion
}

TEST(Conversions, PlaneAndCameraInfoRoundTrip) {
  cellsight::Plane p;
  p.n = Eigen::Vector3d(0.2, -0.5, 0.7).normalized();
  p.d = -0.42;
  const auto back = fromPlaneMsg(toPlaneMsg(p, "cam", ros::Time(12, 34)));
  EXPECT_TRUE(back.n.isApprox(p.n, 1e-12));
  EXPECT_DOUBLE_EQ(back.d, p.d);
  cellsight::LaserPlaneStamped zero;
  EXPECT_THROW(fromPlaneMsg(zero), std::invalid_argument);

  cellsight::CameraIntrinsics c{"c", 1920, 1080, 2400, 2390, 962.5, 537, {-0.08, 0.05, 1e-4, -2e-4, 0.01}};
  const auto ci = toCameraInfo(c, "cam", ros::Time(1, 0));
  const auto c2 = fromCameraInfo(ci);
  EXPECT_EQ(c2.width, 1920);
  EXPECT_DOUBLE_EQ(c2.fy, 2390);
  EXPECT_DOUBLE_EQ(c2.dist[4], 0.01);
  auto broken = ci;
  broken.K[0] = 0;
  EXPECT_THROW(fromCameraInfo(broken), std::invalid_argument);
  broken = ci;
  broken.distortion_model = "equidistant";
  EXPECT_THROW(fromCameraInfo(broken), std::invalid_argument);
}

TEST(Conversions, LaserSweepRoundTripAndRefusals) {
  cellsight::LightSweep s;
  for (int k = 0; k < 3; ++k)
    s.add({0.01f * k, 0.2f, 0.5f}, Eigen::Vector3f(0.f, 0.6f, 0.8f), -0.1f * k, Eigen::Vector3f(0.f, 0.8f, -0.6f));
  s.setFanHalfAngle(0.5);
  const cellsight::LaserSweep m = toLaserSweepMsg(s, "base_link", ros::Time(5, 0));
  EXPECT_EQ(m.header.frame_id, "base_link");
  const cellsight::LightSweep back = fromLaserSweepMsg(m);
  ASSERT_EQ(back.size(), 3u);
  EXPECT_TRUE(back.emitter(2).isApprox(s.emitter(2)));
  EXPECT_TRUE(back.normal(1).isApprox(s.normal(1)));
  EXPECT_TRUE(back.axis(0).isApprox(s.axis(0)));
  EXPECT_FLOAT_EQ(back.offset(2), -0.2f);
  EXPECT_DOUBLE_EQ(back.fanHalfAngle(), 0.5);
  // a sweep without axes (an older publisher): the sheet unbounded
  auto no_axes = m;
  no_axes.axes.clear();
  EXPECT_TRUE(fromLaserSweepMsg(no_axes).axis(1).isZero());
  auto few_axes = m;
  few_axes.axes.pop_back();
  EXPECT_THROW(fromLaserSweepMsg(few_axes), std::invalid_argument);
  auto wide = m;
  wide.fan_half_angle = 2.0;
  EXPECT_THROW(fromLaserSweepMsg(wide), std::invalid_argument);
  auto shorter = m;
  shorter.offsets.pop_back();
  try {
    fromLaserSweepMsg(shorter);
    FAIL() << "arrays of different lengths were taken";
  } catch (const std::invalid_argument& e) {
    EXPECT_NE(std::string(e.what()).find("one entry per frame"), std::string::npos) << e.what();
  }
  auto bad = m;
  bad.normals[1].x = 3;
  EXPECT_THROW(fromLaserSweepMsg(bad), std::invalid_argument);
  bad = m;
  bad.emitters[0].z = std::numeric_limits<double>::quiet_NaN();
  EXPECT_THROW(fromLaserSweepMsg(bad), std::invalid_argument);
}

TEST(Conversions, ImageMessage) {
  cv::Mat m(4, 5, CV_8UC3, cv::Scalar(1, 2, 3));
  const auto msg = toImageMsg(m, "cam", ros::Time(3, 0));
  EXPECT_EQ(msg.encoding, "rgb8");
  EXPECT_EQ(msg.step, 15u);
  EXPECT_EQ(msg.data[2], 3);
  EXPECT_EQ(toImageMsg(cv::Mat(2, 2, CV_8UC1, cv::Scalar(9)), "c", ros::Time()).encoding, "mono8");
  EXPECT_THROW(toImageMsg(cv::Mat(2, 2, CV_32F), "c", ros::Time()), std::invalid_argument);
  EXPECT_EQ(fromNanoseconds(toNanoseconds(ros::Time(5, 7))), ros::Time(5, 7));
}

namespace {
std::string errorOf(const std::function<void()>& f) {
  try {
    f();
  } catch (const std::exception& e) {
    return e.what();
  }
  return "(no error)";
}
}  // namespace

// Issue 19, class 1: sizes and offsets of a PointCloud2 are checked before a point is read.
TEST(Conversions, CloudMessagesWithLyingSizesAreRefused) {
  cellsight::ScanCloud c;
  c.frame_id = "base_link";
  for (int i = 0; i < 5; ++i) c.append(Eigen::Vector3f(0.1f * i, -0.2f, 0.3f + i), 10.f * i);
  c.normals.assign(5, Eigen::Vector3f::UnitZ());
  const sensor_msgs::PointCloud2 good = toCloudMsg(c, ros::Time(1, 0));
  const cellsight::ScanCloud back = fromCloudMsg(good);
  ASSERT_EQ(back.size(), 5u);
  EXPECT_TRUE(back.points[3].isApprox(c.points[3]));
  EXPECT_FLOAT_EQ(back.intensity[4], 40.f);
  ASSERT_EQ(back.normals.size(), 5u);

  {  // zero width under a 2^32 - 1 height: no points, and no walk over 4 billion empty rows (fuzz_ros_msgs)
    auto e = good;
    e.width = 0;
    e.row_step = 0;
    e.height = 0xFFFFFFFFu;
    EXPECT_EQ(fromCloudMsg(e).size(), 0u);
  }
  auto m = good;  // width × point_step overflows 32 bits
  m.width = 0x40000000u;  // × point_step (28) wraps in 32 bits
  EXPECT_NE(errorOf([&] { fromCloudMsg(m); }).find("shorter than"), std::string::npos);
  m = good;  // point_step 0 with a huge width
  m.point_step = 0;
  m.width = 0xFFFFFFFFu;
  EXPECT_NE(errorOf([&] { fromCloudMsg(m); }).find("lies past point_step"), std::string::npos);
  m = good;  // a field past the point
  for (auto& f : m.fields)
    if (f.name == "intensity") f.offset = m.point_step;
  EXPECT_NE(errorOf([&] { fromCloudMsg(m); }).find("'intensity' at offset"), std::string::npos);
  m = good;  // y stored apart from x: read from its own offset
  for (auto& f : m.fields) {
    if (f.name == "y") f.offset = 8;
    else if (f.name == "z") f.offset = 4;
  }
  const cellsight::ScanCloud swapped = fromCloudMsg(m);
  EXPECT_FLOAT_EQ(swapped.points[3].y(), c.points[3].z());
  EXPECT_FLOAT_EQ(swapped.points[3].z(), c.points[3].y());
  m = good;
  m.data.resize(m.data.size() / 2);
  EXPECT_NE(errorOf([&] { fromCloudMsg(m); }).find("shorter than"), std::string::npos);
}

TEST(Conversions, HugeCameraInfoIsRefused) {
  cellsight::CameraIntrinsics c{"c", 1920, 1080, 2400, 2390, 962.5, 537, {0, 0, 0, 0, 0}};
  auto ci = toCameraInfo(c, "cam", ros::Time(1, 0));
  ci.width = ci.height = 60000;
  EXPECT_NE(errorOf([&] { fromCameraInfo(ci); }).find("over the limit"), std::string::npos);
}

// A located part with the turns the scan cannot tell from it: every figure and pose carried over.
TEST(Conversions, DetectionCarriesItsAmbiguousTurns) {
  cellsight::PartDetection d;
  d.model = "holder";
  d.pose = Eigen::Translation3d(0.5, -0.02, 0.025) * Eigen::AngleAxisd(0.3, Eigen::Vector3d(1, 2, 3).normalized());
  d.fitness = 0.91;
  d.coverage = 0.99;
  d.rmse = 3.1e-5;
  d.matcher = "ppf";
  d.cluster = 4;
  d.ambiguous_poses = {Eigen::Isometry3d(Eigen::Translation3d(0.52, -0.01, 0.025) * Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitZ())),
                       Eigen::Isometry3d(Eigen::Translation3d(0.51, 0.0, 0.025) * Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()))};
  d.alternative_score_share = 0.93;
  const cellsight::Detection m = cellsight_ros::toDetectionMsg(d, "object/holder_0");
  EXPECT_EQ(m.model, "holder");
  EXPECT_EQ(m.name, "object/holder_0");
  EXPECT_TRUE(cellsight_ros::fromPoseMsg(m.pose).isApprox(d.pose, 1e-12));
  EXPECT_DOUBLE_EQ(m.fitness, 0.91);
  EXPECT_DOUBLE_EQ(m.coverage, 0.99);
  EXPECT_DOUBLE_EQ(m.rmse, 3.1e-5);
  EXPECT_EQ(m.matcher, "ppf");
  EXPECT_EQ(m.cluster, 4);
  ASSERT_EQ(m.ambiguous_poses.size(), 2u);
  for (size_t i = 0; i < 2; ++i) EXPECT_TRUE(cellsight_ros::fromPoseMsg(m.ambiguous_poses[i]).isApprox(d.ambiguous_poses[i], 1e-12)) << i;
  EXPECT_DOUBLE_EQ(m.alternative_score_share, 0.93);
  // not ambiguous: no turns, the share as measured
  d.ambiguous_poses.clear();
  d.alternative_score_share = 0.4;
  const cellsight::Detection plain = cellsight_ros::toDetectionMsg(d, "object/holder_0");
  EXPECT_TRUE(plain.ambiguous_poses.empty());
  EXPECT_DOUBLE_EQ(plain.alternative_score_share, 0.4);
}

TEST(Conversions, GraspPlanTrajectoryRoundTripAndRefusals) {
  const std::array<std::string, 6> names{"joint_1", "joint_2", "joint_3", "joint_4", "joint_5", "joint_6"};
  cellsight::PartPlan p;
  p.status = cellsight::PlanStatus::kOk;
  p.part = {"housing_0", "housing", Eigen::Isometry3d(Eigen::Translation3d(0.5, 0.1, 0)), {}};
  p.poses = {{"grasp", Eigen::Isometry3d(Eigen::Translation3d(0.5, 0.1, 0.02)), cellsight::JointVector::Zero()}};
  p.T_base_target = Eigen::Isometry3d(Eigen::Translation3d(0.3, 0.0, 0));
  for (int i = 0; i < 5; ++i) {
    p.trajectory.positions.push_back(cellsight::JointVector::Constant(0.1 * i));
    p.trajectory.velocities.push_back(cellsight::JointVector::Constant(0.2));
    p.trajectory.times.push_back(0.5 * i);
  }
  p.grasp_index = 1;
  p.release_index = 3;
  p.passed_over = {"blade_0: unreachable: far away"};
  const cellsight::GraspPlan m = toGraspPlanMsg(p, names, "base_link", ros::Time(3, 0));
  EXPECT_EQ(m.status, cellsight::GraspPlan::OK);
  EXPECT_EQ(m.object, "housing_0");
  EXPECT_EQ(m.passed_over.size(), 1u);
  EXPECT_NEAR(fromPoseMsg(m.target).translation().x(), 0.3, 1e-12);
  cellsight::PartPlan ambiguous = p;
  ambiguous.status = cellsight::PlanStatus::kAmbiguousPose;
  EXPECT_EQ(toGraspPlanMsg(ambiguous, names, "base_link", ros::Time(3, 0)).status, cellsight::GraspPlan::AMBIGUOUS_POSE);
  const cellsight::TimedTrajectory t = fromTrajectoryMsg(m.trajectory, names);
  ASSERT_EQ(t.positions.size(), 5u);
  for (size_t i = 0; i < 5; ++i) {
    EXPECT_LT((t.positions[i] - p.trajectory.positions[i]).norm(), 1e-12);
    EXPECT_NEAR(t.times[i], p.trajectory.times[i], 1e-9);
  }
  // joints in another order are read by name
  auto shuffled = m.trajectory;
  std::swap(shuffled.joint_names[0], shuffled.joint_names[5]);
  for (auto& pt : shuffled.points) {
    std::swap(pt.positions[0], pt.positions[5]);
    pt.positions[0] += 1.0;  // now joint_6's column
  }
  EXPECT_NEAR(fromTrajectoryMsg(shuffled, names).positions[2][5], 0.2 + 1.0, 1e-12);
  auto bad = m.trajectory;
  bad.joint_names[2] = "elbow";
  EXPECT_NE(errorOf([&] { fromTrajectoryMsg(bad, names); }).find("no joint 'joint_3'"), std::string::npos);
  bad = m.trajectory;
  bad.points[2].time_from_start = bad.points[1].time_from_start;
  EXPECT_NE(errorOf([&] { fromTrajectoryMsg(bad, names); }).find("times must increase"), std::string::npos);
  bad = m.trajectory;
  bad.points[4].positions[1] = std::nan("");
  EXPECT_NE(errorOf([&] { fromTrajectoryMsg(bad, names); }).find("not finite"), std::string::npos);
  bad = m.trajectory;
  bad.points[0].positions.pop_back();
  EXPECT_NE(errorOf([&] { fromTrajectoryMsg(bad, names); }).find("5 positions"), std::string::npos);
  bad.points.clear();
  EXPECT_NE(errorOf([&] { fromTrajectoryMsg(bad, names); }).find("no points"), std::string::npos);
  // a refusal carries its reason and no trajectory
  p.status = cellsight::PlanStatus::kNoPath;
  p.reason = "carried housing vs object blade";
  const cellsight::GraspPlan r = toGraspPlanMsg(p, names, "base_link", ros::Time(3, 0));
  EXPECT_EQ(r.status, cellsight::GraspPlan::NO_PATH);
  EXPECT_EQ(r.reason, p.reason);
  EXPECT_TRUE(r.trajectory.points.empty());
}
