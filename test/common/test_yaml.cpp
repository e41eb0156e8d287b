#include <gtest/gtest.h>
#include <sys/stat.h>
#include <unistd.h>
#include <sys/wait.h>
#include <unistd.h>

#include <fstream>

#include "cellsight/common/calibration.hpp"
#include "cellsight/common/file_io.hpp"
#include "cellsight/common/trajectory.hpp"
#include "cellsight/common/yaml_reader.hpp"
#include "test_helpers.hpp"

using cellsight::ConfigError;
using cellsight::YamlMap;

using cellsight_test::errorOf;

TEST(Yaml, UnknownKeyIsReportedWithFileAndPath) {
  const std::string dir = cellsight_test::tempDir();
  cellsight_test::writeText(dir + "/a.yaml", "outer: {inner: 1, typo: 2}\n");
  const std::string msg = errorOf([&] {
    YamlMap m(cellsight::loadYamlFile(dir + "/a.yaml"), dir + "/a.yaml");
    YamlMap o = m.getMap("outer");
    o.getInt("inner");
    o.finish();
  });
  EXPECT_NE(msg.find(dir + "/a.yaml"), std::string::npos) << msg;
  EXPECT_NE(msg.find("outer.typo"), std::string::npos) << msg;
}

TEST(Yaml, SyntaxErrorNamesFileAndLine) {
  const std::string dir = cellsight_test::tempDir();
  cellsight_test::writeText(dir + "/b.yaml", "a: 1\nb: [1, 2\nc: 3\n");
  const std::string msg = errorOf([&] { cellsight::loadYamlFile(dir + "/b.yaml"); });
  EXPECT_NE(msg.find("b.yaml"), std::string::npos) << msg;
  EXPECT_NE(msg.find("line"), std::string::npos) << msg;
}

TEST(Yaml, WrongTypeAndMissingKeyAreNamed) {
  YAML::Node n = YAML::Load("x: hello\nv: [1, 2]\n");
  YamlMap m(n, "f.yaml");
  EXPECT_NE(errorOf([&] { m.getDouble("x"); }).find("f.yaml: x: expected a number"), std::string::npos);
  EXPECT_NE(errorOf([&] { m.getVector3("v"); }).find("expected 3 numbers"), std::string::npos);
  EXPECT_NE(errorOf([&] { m.getInt("missing"); }).find("missing: required key is missing"),
            std::string::npos);
}

TEST(Yaml, PoseFromRpyAndQuatAgree) {
  YAML::Node n = YAML::Load(
      "a: {xyz: [1, 2, 3], rpy: [0.1, -0.2, 0.3]}\n"
      "b: {xyz: [0, 0, 0], quat: [0, 0, 0.7071067811865476, 0.7071067811865476]}\n"
      "c: {xyz: [0, 0, 0], quat: [0, 0, 2, 2]}\n");
  YamlMap m(n, "p.yaml");
  const Eigen::Isometry3d a = m.getPose("a");
  const Eigen::Matrix3d expected = (Eigen::AngleAxisd(0.3, Eigen::Vector3d::UnitZ()) *
                                    Eigen::AngleAxisd(-0.2, Eigen::Vector3d::UnitY()) *
                                    Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitX()))
                                       .toRotationMatrix();
  EXPECT_TRUE(a.linear().isApprox(expected, 1e-12));
  EXPECT_TRUE(a.translation().isApprox(Eigen::Vector3d(1, 2, 3)));
  EXPECT_NEAR((m.getPose("b").linear() * Eigen::Vector3d::UnitX() - Eigen::Vector3d::UnitY()).norm(), 0, 1e-9);
  EXPECT_THROW(m.getPose("c"), ConfigError);  // not unit length
}

TEST(Calibration, TransformRoundTripAndCorruptFileKeepsOld) {
  const std::string dir = cellsight_test::tempDir();
  cellsight::TransformCalibration c;
  c.parent_frame = "flange";
  c.child_frame = "laser";
  c.T_parent_child = Eigen::Translation3d(0.06, 0, 0.04) * Eigen::AngleAxisd(0.5, Eigen::Vector3d(1, 2, 3).normalized());
  c.residual_rms = 1.5e-5;
  c.method = "test";
  c.date = cellsight::isoDateNow();
  cellsight::saveTransformCalibration(dir + "/laser.yaml", c);
  const auto back = cellsight::loadTransformCalibration(dir + "/laser.yaml");
  EXPECT_EQ(back.parent_frame, "flange");
  EXPECT_EQ(back.child_frame, "laser");
  EXPECT_TRUE(back.T_parent_child.isApprox(c.T_parent_child, 1e-12));
  EXPECT_DOUBLE_EQ(back.residual_rms, c.residual_rms);
  // A failed atomic write (target folder missing) throws and leaves nothing half-written.
  EXPECT_THROW(cellsight::writeFileAtomic(dir + "/missing/x.yaml", "a: 1\n"), std::runtime_error);
  // A corrupt calibration in a folder is refused with the file named.
  cellsight_test::writeText(dir + "/bad.yaml", "parent_frame: base_link\nchild_frame: base_link\ntransform: {xyz: [0,0,0]}\n");
  const std::string msg = errorOf([&] { cellsight::loadCalibrationFolder(dir); });
  EXPECT_NE(msg.find("bad.yaml: child_frame"), std::string::npos) << msg;
}

TEST(Calibration, TwoFilesForOneFrameAreRefused) {
  const std::string dir = cellsight_test::tempDir();
  cellsight::TransformCalibration c;
  c.parent_frame = "flange";
  c.child_frame = "laser";
  cellsight::saveTransformCalibration(dir + "/laser.yaml", c);
  EXPECT_EQ(cellsight::loadCalibrationFolder(dir).transforms.size(), 1u);
  c.parent_frame = "base_link";  // a second file giving the laser another parent
  cellsight::saveTransformCalibration(dir + "/laser_old.yaml", c);
  const std::string msg = errorOf([&] { cellsight::loadCalibrationFolder(dir); });
  EXPECT_NE(msg.find("laser_old.yaml: frame 'laser' is already calibrated in"), std::string::npos) << msg;
}

TEST(FileIo, AnInterruptedWriteLeavesNoTemporaryBehind) {
  const std::string dir = cellsight_test::tempDir();
  const pid_t child = fork();  // a process that is surely gone: a writer killed mid-write
  if (child == 0) _exit(0);
  ASSERT_GT(child, 0);
  waitpid(child, nullptr, 0);
  const std::string stale = dir + "/x.yaml.tmp." + std::to_string(child) + ".a1B2c3";
  const std::string live = dir + "/x.yaml.tmp." + std::to_string(getppid()) + ".d4E5f6";  // a writer still running
  cellsight_test::writeText(stale, "half written");
  cellsight_test::writeText(live, "being written");
  cellsight::writeFileAtomic(dir + "/x.yaml", "a: 1\n");
  EXPECT_FALSE(std::ifstream(stale).good()) << "the dead writer's temporary is still there";
  EXPECT_TRUE(std::ifstream(live).good()) << "a running writer's temporary was removed";
  EXPECT_TRUE(std::ifstream(dir + "/x.yaml").good());
}

// A symlink planted where a writer's temporary would be (the old `<file>.tmp.<pid>`) is never
// followed: its target stays as it was, the file is written.
TEST(FileIo, APlantedSymlinkIsNotFollowed) {
  const std::string dir = cellsight_test::tempDir();
  const std::string victim = dir + "/victim.txt";
  cellsight_test::writeText(victim, "keep me");
  const std::string link = dir + "/x.yaml.tmp." + std::to_string(getpid());
  ASSERT_EQ(symlink(victim.c_str(), link.c_str()), 0);
  cellsight::writeFileAtomic(dir + "/x.yaml", "a: 1\n");
  std::ifstream v(victim);
  std::string kept((std::istreambuf_iterator<char>(v)), std::istreambuf_iterator<char>());
  EXPECT_EQ(kept, "keep me");
  std::ifstream x(dir + "/x.yaml");
  std::string written((std::istreambuf_iterator<char>(x)), std::istreambuf_iterator<char>());
  EXPECT_EQ(written, "a: 1\n");
  struct stat st {};
  ASSERT_EQ(stat((dir + "/x.yaml").c_str(), &st), 0);
  EXPECT_EQ(st.st_mode & 0777, 0644u);
}

// Issue 19, class 1: a trajectory's step count is bounded before poses are made.
TEST(Trajectory, AbsurdStepCountsAreRefusedWithTheLimit) {
  const std::string dir = cellsight_test::tempDir();
  const std::string file = dir + "/t.yaml";
  std::ofstream(file) << "trajectories:\n  huge: {type: linear, steps: 2147483647, start: {xyz: [0.5, 0, 0.3], rpy: [3.14159, 0, 0]},"
                         " end: {xyz: [0.5, 0.1, 0.3], rpy: [3.14159, 0, 0]}}\n";
  try {
    cellsight::loadTrajectories(file);
    FAIL() << "2^31 steps accepted";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("2 to 100000 steps"), std::string::npos) << e.what();
  }
}

// A trajectory asked for by name: found, or a ConfigError that lists what the file has.
TEST(Trajectory, UnknownNameListsTheFilesTrajectories) {
  const std::string file = cellsight_test::tempDir() + "/t.yaml";
  std::ofstream(file) << "trajectories:\n  one: {type: linear, steps: 3, start: {xyz: [0.5, 0, 0.3], rpy: [3.14159, 0, 0]},"
                         " end: {xyz: [0.5, 0.1, 0.3], rpy: [3.14159, 0, 0]}}\n";
  EXPECT_EQ(cellsight::loadTrajectory(file, "one").poses.size(), 3u);
  try {
    cellsight::loadTrajectory(file, "two");
    FAIL() << "an unknown trajectory was answered";
  } catch (const ConfigError& e) {
    EXPECT_NE(std::string(e.what()).find("no trajectory 'two' (the file has: one)"), std::string::npos) << e.what();
  }
}
