// The simulated cell as built: the robot's kinematic error (KDL), the seeded mounting offsets of
// the scene's as_built section and the `perfect` switch.
#include <gtest/gtest.h>

#include <cmath>
#include <fstream>

#include "cellsight/common/errors.hpp"
#include "cellsight/common/trajectory.hpp"
#include "cellsight/sim/robot_model.hpp"
#include "cellsight/sim/scene.hpp"
#include "sim/sim_test_scenes.hpp"

using namespace cellsight;

namespace {
const std::string kRoot = CELLSIGHT_SOURCE_DIR;

RobotErrorConfig demoRobot() {
  RobotErrorConfig c;
  c.enabled = true;
  c.seed = 5;
  return c;
}
}  // namespace

TEST(RobotErrorModel, DisabledIsExact) {
  const RobotErrorModel m;
  const Eigen::Isometry3d P = Eigen::Translation3d(0.5, 0.1, 0.3) * Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX());
  EXPECT_TRUE(m.actual(P, 3).isApprox(P, 0));
  EXPECT_TRUE(m.reported(P).isApprox(P, 0));
}

TEST(RobotErrorModel, AbsoluteErrorOfAFewTenthsAlongTheDemoSweepAndItsInverse) {
  const RobotErrorModel m(demoRobot());
  const Trajectory t = loadTrajectories(kRoot + "/config/trajectories.yaml").at("demo_sweep");
  double max_err = 0, min_err = 1;
  for (const auto& P : t.poses) {
    const Eigen::Isometry3d A = m.actualSystematic(P);
    const double e = (A.translation() - P.translation()).norm();
    max_err = std::max(max_err, e);
    min_err = std::min(min_err, e);
    // what the controller reports when the flange really is at A: P again
    const Eigen::Isometry3d R = m.reported(A);
    EXPECT_LT((R.translation() - P.translation()).norm(), 1e-7);
    EXPECT_LT(Eigen::AngleAxisd(R.linear().transpose() * P.linear()).angle(), 1e-7);
  }
  std::printf("robot absolute error along demo_sweep: %.3f .. %.3f mm\n", min_err * 1e3, max_err * 1e3);
  EXPECT_GT(min_err, 0.02e-3);
  EXPECT_LT(max_err, 1.0e-3);
  // the same seed builds the same arm
  const RobotErrorModel again(demoRobot());
  EXPECT_TRUE(again.actual(t.poses[7], 11).isApprox(m.actual(t.poses[7], 11), 1e-12));
}

TEST(RobotErrorModel, RepeatabilityScatterHasTheConfiguredSigma) {
  const RobotErrorModel m(demoRobot());
  const Eigen::Isometry3d P = Eigen::Translation3d(0.5, 0.0, 0.3) * Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX());
  const Eigen::Vector3d s = m.actualSystematic(P).translation();
  double sum2 = 0;
  const int n = 400;
  for (int k = 0; k < n; ++k) sum2 += (m.actual(P, static_cast<uint64_t>(k)).translation() - s).squaredNorm();
  const double sigma_per_axis = std::sqrt(sum2 / (3.0 * n));
  EXPECT_NEAR(sigma_per_axis, demoRobot().repeatability_mm * 1e-3, 0.15 * demoRobot().repeatability_mm * 1e-3);
}

TEST(RobotErrorModel, UnreachablePoseIsRefused) {
  const RobotErrorModel m(demoRobot());
  const Eigen::Isometry3d far = Eigen::Translation3d(2.0, 0.0, 0.3) * Eigen::AngleAxisd(M_PI, Eigen::Vector3d::UnitX());
  EXPECT_THROW(m.actual(far, 0), std::runtime_error);
  RobotErrorConfig bad = demoRobot();
  bad.link_mm = -1;
  EXPECT_THROW(RobotErrorModel{bad}, std::invalid_argument);
}

TEST(SceneAsBuilt, MountsOffTheDrawingUnlessPerfect) {
  Scene s = loadScene(kRoot + "/config/scenes/demo.yaml");
  ASSERT_FALSE(s.as_built.perfect);
  EXPECT_TRUE(s.as_built.robot.enabled);
  const double dc = (s.scanner_camera.T_base_camera.translation() - s.as_built.drawn_scanner_camera.translation()).norm();
  const double dl = (s.laser.T_flange_laser.translation() - s.as_built.drawn_laser.translation()).norm();
  EXPECT_GT(dc, 0.1e-3);
  EXPECT_LT(dc, 10e-3);
  EXPECT_GT(dl, 0.05e-3);
  EXPECT_LT(dl, 5e-3);
  makePerfect(s);
  EXPECT_TRUE(s.scanner_camera.T_base_camera.isApprox(s.as_built.drawn_scanner_camera, 0));
  EXPECT_TRUE(s.laser.T_flange_laser.isApprox(s.as_built.drawn_laser, 0));
  EXPECT_FALSE(s.as_built.robot.enabled);
}

TEST(SceneAsBuilt, BadValuesNameTheField) {
  const std::string dir = cellsight_test::tempDir();
  std::ifstream in(kRoot + "/config/scenes/demo.yaml");
  std::string text((std::istreambuf_iterator<char>(in)), std::istreambuf_iterator<char>());
  const std::string key = "joint_offset_deg: 0.01";
  ASSERT_NE(text.find(key), std::string::npos);
  text.replace(text.find(key), key.size(), "joint_offset_deg: -0.01");
  const std::string path = dir + "/scenes/bad.yaml";
  ASSERT_EQ(std::system(("mkdir -p " + dir + "/scenes && ln -sfn " + kRoot + "/config/models " + dir + "/models").c_str()), 0);
  std::ofstream(path) << text;
  try {
    loadScene(path);
    FAIL() << "a negative sigma was accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("joint_offset_deg"), std::string::npos) << e.what();
  }
}
