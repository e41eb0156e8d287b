#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "cellsight/common/plane.hpp"
#include "cellsight/common/errors.hpp"
#include "cellsight/localization/light_sweep.hpp"
#include "test_helpers.hpp"

using namespace cellsight;

namespace {

/// A sheet x = x_k (normal +x) moving from x = 0 to 0.1 m in 1 cm steps, its emitter 0.5 m up.
LightSweep translatingSheet() {
  LightSweep s;
  for (int k = 0; k <= 10; ++k) s.add({0.01f * k, 0.f, 0.5f}, Eigen::Vector3f::UnitX(), -0.01f * k);
  return s;
}

using FlangePoses = std::vector<Eigen::Isometry3d, Eigen::aligned_allocator<Eigen::Isometry3d>>;

/// The demo's laser mount (60 mm beside the flange, leaning 0.5 rad) and 20 tool-down flange
/// poses stepping 1 cm along y, 0.4 m above the table.
Eigen::Isometry3d laserMount() {
  Eigen::Isometry3d T_flange_laser = Eigen::Isometry3d::Identity();
  T_flange_laser.translation() = Eigen::Vector3d(0, 0.06, 0.04);
  T_flange_laser.linear() = Eigen::AngleAxisd(0.5, Eigen::Vector3d::UnitX()).toRotationMatrix();
  return T_flange_laser;
}
FlangePoses downSweep() {
  FlangePoses flange;
  for (int k = 0; k < 20; ++k) {
    Eigen::Isometry3d F = Eigen::Isometry3d::Identity();
    F.linear() = Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX()).toRotationMatrix();  // tool down
    F.translation() = Eigen::Vector3d(0.5, -0.1 + 0.01 * k, 0.4);
    flange.push_back(F);
  }
  return flange;
}

}  // namespace

TEST(LightSweep, EmitterOfTheSheetThroughAPoint) {
  const LightSweep s = translatingSheet();
  Eigen::Vector3f e;
  // between frames 3 and 4: the emitter interpolated to where the sheet crossed the point
  ASSERT_TRUE(s.emitterFor({0.035f, 0.02f, 0.f}, &e));
  EXPECT_NEAR(e.x(), 0.035f, 1e-6f);
  EXPECT_NEAR(e.z(), 0.5f, 1e-6f);
  // on a frame's sheet, and on the first and the last
  for (const float x : {0.f, 0.06f, 0.1f}) {
    ASSERT_TRUE(s.emitterFor({x, -0.01f, 0.02f}, &e)) << x;
    EXPECT_NEAR(e.x(), x, 1e-6f);
  }
  // the sheet never passed points before the first frame or after the last
  EXPECT_FALSE(s.emitterFor({-0.001f, 0.f, 0.f}, &e));
  EXPECT_FALSE(s.emitterFor({0.2f, 0.f, 0.f}, &e));
  // the same sweep run backwards gives the same emitter
  LightSweep back;
  for (int k = 10; k >= 0; --k) back.add({0.01f * k, 0.f, 0.5f}, Eigen::Vector3f::UnitX(), -0.01f * k);
  ASSERT_TRUE(back.emitterFor({0.035f, 0.02f, 0.f}, &e));
  EXPECT_NEAR(e.x(), 0.035f, 1e-6f);
}

TEST(LightSweep, FromFlangePosesUsesTheLaserFrame) {
  // laser frame: origin at the emitter, the sheet its y = 0 plane
  const Eigen::Isometry3d T_flange_laser = laserMount();
  const FlangePoses flange = downSweep();
  const LightSweep s = LightSweep::fromFlangePoses(flange, T_flange_laser);
  ASSERT_EQ(s.size(), 20u);
  EXPECT_LT((s.axis(7).cast<double>() - (flange[7] * T_flange_laser).linear().col(2)).norm(), 1e-6) << "the fan's axis: laser z";
  // a point on frame 7's sheet, on the table: lit from frame 7's emitter
  const Eigen::Isometry3d L7 = flange[7] * T_flange_laser;
  const Plane sheet = laserPlane(L7);
  const Eigen::Vector3d beam = L7.linear().col(2);  // the central beam, in the sheet
  const Eigen::Vector3d p = L7.translation() + beam * ((0.0 - L7.translation().z()) / beam.z());
  ASSERT_NEAR(sheet.distance(p), 0.0, 1e-9);
  Eigen::Vector3f e;
  ASSERT_TRUE(s.emitterFor(p.cast<float>(), &e));
  EXPECT_LT((e.cast<double>() - L7.translation()).norm(), 1e-5);
}

// A projector's fan lights its sheet only within the fan's half-angle of its axis: a point of
// the sheet beyond it was never lit, whatever the frames bracketing it.
TEST(LightSweep, TheFanBoundsTheSheet) {
  const Eigen::Isometry3d T_flange_laser = laserMount();
  const FlangePoses flange = downSweep();
  const double half = 0.5;  // rad
  const LightSweep fan = LightSweep::fromFlangePoses(flange, T_flange_laser, half);
  const LightSweep open = LightSweep::fromFlangePoses(flange, T_flange_laser);
  EXPECT_DOUBLE_EQ(fan.fanHalfAngle(), half);
  // rays of frame 7's sheet at 0.9 and 1.1 x the half-angle from its axis, down to the table
  const Eigen::Isometry3d L7 = flange[7] * T_flange_laser;
  for (const double share : {0.0, 0.9, -0.9, 1.1, -1.1}) {
    const Eigen::Vector3d dir = L7.linear() * Eigen::Vector3d(std::sin(share * half), 0, std::cos(share * half));
    const Eigen::Vector3d p = L7.translation() + dir * ((0.0 - L7.translation().z()) / dir.z());
    Eigen::Vector3f e;
    EXPECT_TRUE(open.emitterFor(p.cast<float>(), &e)) << share;
    EXPECT_EQ(fan.emitterFor(p.cast<float>(), &e), std::abs(share) < 1) << share;
  }
  LightSweep s;
  EXPECT_THROW(s.setFanHalfAngle(-0.1), std::invalid_argument);
  EXPECT_THROW(s.setFanHalfAngle(M_PI / 2), std::invalid_argument);
  EXPECT_THROW(s.add(Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitX(), 0.f, Eigen::Vector3f(0.f, 0.f, 2.f)),
               std::invalid_argument);
}

TEST(LightSweep, BadFramesAreRefusedAndShortSweepsLightNothing) {
  LightSweep s;
  Eigen::Vector3f e;
  EXPECT_FALSE(s.emitterFor(Eigen::Vector3f::Zero(), &e));
  s.add(Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitX(), 0.f);
  EXPECT_FALSE(s.emitterFor(Eigen::Vector3f::Zero(), &e)) << "one frame brackets nothing";
  try {
    s.add(Eigen::Vector3f::Zero(), Eigen::Vector3f(2.f, 0.f, 0.f), 0.f);
    FAIL() << "a normal of length 2 was taken";
  } catch (const std::invalid_argument& ex) {
    EXPECT_NE(std::string(ex.what()).find("unit length"), std::string::npos) << ex.what();
  }
  EXPECT_THROW(s.add(Eigen::Vector3f::Constant(NAN), Eigen::Vector3f::UnitX(), 0.f), std::invalid_argument);
  EXPECT_THROW(s.add(Eigen::Vector3f::Zero(), Eigen::Vector3f::UnitX(), INFINITY), std::invalid_argument);
  EXPECT_EQ(s.size(), 1u);
}

// The sweep's text (--dump-clusters) reads back frame for frame; a broken file is refused with
// its name and line.
TEST(LightSweep, SavedAndLoadedAsText) {
  LightSweep s = translatingSheet();
  s.setFanHalfAngle(0.525);
  const std::string dir = cellsight_test::tempDir();
  saveSweep(dir + "/sweep.txt", s);
  const LightSweep r = loadSweep(dir + "/sweep.txt");
  ASSERT_EQ(r.size(), s.size());
  EXPECT_DOUBLE_EQ(r.fanHalfAngle(), 0.525);
  for (size_t k = 0; k < s.size(); ++k) {
    EXPECT_TRUE(r.emitter(k).isApprox(s.emitter(k), 1e-6f)) << k;
    EXPECT_TRUE(r.normal(k).isApprox(s.normal(k), 1e-6f)) << k;
    EXPECT_NEAR(r.offset(k), s.offset(k), 1e-7f) << k;
    EXPECT_EQ(r.axis(k), s.axis(k)) << k;
  }
  auto bad = [&](const std::string& text) {
    std::ofstream(dir + "/bad.txt") << text;
    return cellsight_test::errorOf([&] { loadSweep(dir + "/bad.txt"); });
  };
  EXPECT_NE(bad("0 0 0.5 1 0 0 0 0 0\n").find("bad.txt:1: a frame is ten numbers"), std::string::npos);
  EXPECT_NE(bad("# fan_half_angle 0.5\n0 0 0.5 2 0 0 0 0 0 0\n").find("bad.txt:2: LightSweep"), std::string::npos);
  EXPECT_NE(bad("# fan_half_angle x\n").find("not a number"), std::string::npos);
  EXPECT_NE(bad("0 0 0.5 1 0 0 0 0 0 0 7\n").find("ten numbers"), std::string::npos);
  EXPECT_NE(cellsight_test::errorOf([&] { loadSweep(dir + "/none.txt"); }).find("cannot open"), std::string::npos);
}
