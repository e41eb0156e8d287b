// The robot bridge: pose conventions, the line protocol, and a live server against well-behaved
// and malformed clients (garbage, 1 MB lines, slow-loris, disconnects mid-line, 100 connections).
#include <gtest/gtest.h>

#include <cmath>

#include <atomic>
#include <chrono>
#include <memory>
#include <random>
#include <thread>

#include "cellsight/bridge/line_client.hpp"
#include "cellsight/bridge/robot_bridge.hpp"

using namespace cellsight;

namespace {

Eigen::Isometry3d samplePose() {
  Eigen::Isometry3d T = Eigen::Isometry3d::Identity();
  T.translation() = Eigen::Vector3d(0.4123, -0.2057, 0.0315);
  T.linear() = (Eigen::AngleAxisd(0.7, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(-0.2, Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  return T;
}

struct Cell {
  std::atomic<int> adjusts{0}, captures{0};
  BridgeCallbacks callbacks() {
    BridgeCallbacks cb;
    cb.adjust = [this] {
      ++adjusts;
      BridgeAnswer a;
      a.ok = true;
      a.fixture = "A";
      a.type = "A";
      a.program = "weld_a";
      a.ucs = samplePose();
      return a;
    };
    cb.ucs = [](const std::string& program) {
      BridgeAnswer a;
      if (program == "far_z" || program == "nan_z") {  // a registry or a teach gone wrong
        a.ok = true;
        a.program = program;
        a.ucs = samplePose();
        a.ucs.translation().x() = program == "far_z" ? 1e300 : std::nan("");
        return a;
      }
      if (program != "weld_a") {
        a.code = "UNKNOWN_PROGRAM";
        a.message = "no fixture runs " + program;
        return a;
      }
      a.ok = true;
      a.program = program;
      a.ucs = samplePose();
      a.stale = true;
      return a;
    };
    cb.in_position = [this](uint64_t seq) {
      ++captures;
      BridgeAnswer a;
      a.ok = seq != 13;
      a.message = "camera timed out\nsecond line";
      return a;
    };
    return cb;
  }
};

RobotBridgeConfig testConfig() {
  RobotBridgeConfig c;
  c.server.line_timeout = 0.4;
  c.server.idle_timeout = 30;
  c.server.max_clients = 16;
  return c;
}

}  // namespace

TEST(RobotConventions, EveryConventionRoundTrips) {
  const Eigen::Isometry3d T = samplePose();
  for (auto c : {PoseConvention::kKuka, PoseConvention::kAbb, PoseConvention::kFanuc, PoseConvention::kRep103}) {
    const Eigen::Isometry3d back = parseRobotPose(formatRobotPose(T, c), c);
    EXPECT_LT((back.translation() - T.translation()).norm(), 1e-6) << poseConventionName(c);
    EXPECT_LT(Eigen::AngleAxisd(back.linear().transpose() * T.linear()).angle(), 1e-5) << poseConventionName(c);
  }
  // known values: a frame 100 mm along x, turned 90° about z
  Eigen::Isometry3d R = Eigen::Isometry3d::Identity();
  R.translation().x() = 0.1;
  R.linear() = Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitZ()).toRotationMatrix();
  EXPECT_EQ(formatRobotPose(R, PoseConvention::kKuka), "100.000 0.000 0.000 90.0000 0.0000 0.0000");
  EXPECT_EQ(formatRobotPose(R, PoseConvention::kFanuc), "100.000 0.000 0.000 0.0000 0.0000 90.0000");
  EXPECT_EQ(formatRobotPose(R, PoseConvention::kAbb), "100.000 0.000 0.000 0.7071068 0.0000000 0.0000000 0.7071068");
  // gimbal lock (B = 90°): the pose survives the round trip, C set to 0
  Eigen::Isometry3d G = Eigen::Isometry3d::Identity();
  G.linear() = (Eigen::AngleAxisd(0.4, Eigen::Vector3d::UnitZ()) * Eigen::AngleAxisd(M_PI / 2, Eigen::Vector3d::UnitY()) *
                Eigen::AngleAxisd(0.1, Eigen::Vector3d::UnitX()))
                   .toRotationMatrix();
  for (auto c : {PoseConvention::kKuka, PoseConvention::kFanuc, PoseConvention::kRep103}) {
    const Eigen::Isometry3d back = parseRobotPose(formatRobotPose(G, c), c);
    EXPECT_LT(Eigen::AngleAxisd(back.linear().transpose() * G.linear()).angle(), 1e-5) << poseConventionName(c);
  }
  EXPECT_THROW(parseRobotPose("1 2 3", PoseConvention::kKuka), std::invalid_argument);
  EXPECT_THROW(parseRobotPose("1 2 3 4 5 nan", PoseConvention::kKuka), std::invalid_argument);
  EXPECT_THROW(parseRobotPose("1 2 3 0 0 0 0", PoseConvention::kAbb), std::invalid_argument);
  EXPECT_THROW(parsePoseConvention("yaskawa"), std::invalid_argument);
}

TEST(BridgeProtocol, RequestsAreParsedStrictly) {
  BridgeRequest r;
  std::string e;
  ASSERT_TRUE(parseBridgeRequest("INPOS 42", r, e));
  EXPECT_EQ(r.kind, BridgeRequest::Kind::kInPosition);
  EXPECT_EQ(r.seq, 42u);
  ASSERT_TRUE(parseBridgeRequest("  ucs   weld_a ", r, e));
  EXPECT_EQ(r.name, "weld_a");
  for (const std::string& bad : std::vector<std::string>{"", "FLY", "UCS", "UCS a b", "INPOS -1", "INPOS 12345678901", "HELLO bad/name",
                                std::string("PING\x01", 5), "ADJUST now"}) {
    EXPECT_FALSE(parseBridgeRequest(bad, r, e)) << bad;
    EXPECT_FALSE(e.empty());
  }
}

TEST(RobotBridge, AControllerAdjustsAndDrivesAScan) {
  Cell cell;
  RobotBridge bridge(testConfig(), cell.callbacks());
  LineClient robot("127.0.0.1", bridge.port());
  EXPECT_EQ(robot.request("HELLO kuka_krc4"), "OK HELLO cellsight kuka");
  EXPECT_EQ(robot.request("PING"), "OK PONG");
  const std::string adjust = robot.request("ADJUST");
  EXPECT_EQ(adjust.rfind("OK ADJUST A A weld_a ", 0), 0u) << adjust;
  const Eigen::Isometry3d ucs = parseRobotPose(adjust.substr(std::string("OK ADJUST A A weld_a ").size()), PoseConvention::kKuka);
  EXPECT_LT((ucs.translation() - samplePose().translation()).norm(), 1e-6);
  EXPECT_EQ(robot.request("UCS weld_a").substr(0, 13), "OK UCS weld_a");
  EXPECT_NE(robot.request("UCS weld_a").find("STALE"), std::string::npos);
  EXPECT_EQ(robot.request("UCS glue_b").rfind("ERR UNKNOWN_PROGRAM", 0), 0u);
  // no value outside the cell reaches the controller
  for (const char* program : {"far_z", "nan_z"}) {
    const std::string far = robot.request(std::string("UCS ") + program);
    EXPECT_EQ(far.rfind("ERR RANGE the user frame of " + std::string(program) + " is not sent", 0), 0u) << far;
    EXPECT_LT(far.size(), 200u) << far;
  }
  for (int seq = 1; seq <= 5; ++seq) EXPECT_EQ(robot.request("INPOS " + std::to_string(seq)), "OK CAPTURED " + std::to_string(seq));
  // a failed capture: one line, the message's newline flattened
  const std::string failed = robot.request("INPOS 13");
  EXPECT_EQ(failed.rfind("ERR CAPTURE 13 camera timed out", 0), 0u) << failed;
  EXPECT_EQ(cell.captures.load(), 6);
  EXPECT_EQ(robot.request("QUIT"), "OK BYE");
  EXPECT_TRUE(robot.closedByServer(2.0));
}

TEST(RobotBridge, MalformedClientsAreClosedWithAReasonAndTheBridgeKeepsServing) {
  Cell cell;
  RobotBridge bridge(testConfig(), cell.callbacks());
  const int port = bridge.port();
  {  // garbage, answered line by line; ten in a row close the connection
    LineClient c("127.0.0.1", port);
    EXPECT_EQ(c.request("\x7f\x80\xff").rfind("ERR SYNTAX", 0), 0u);
    EXPECT_EQ(c.request("PING"), "OK PONG");  // the count starts again after a good request
    std::string last;
    for (int i = 0; i < 10; ++i) last = c.request("FLY " + std::to_string(i));
    EXPECT_EQ(last.rfind("ERR TOO_MANY_ERRORS", 0), 0u) << last;
    EXPECT_TRUE(c.closedByServer(2.0));
  }
  {  // a 1 MB line
    LineClient c("127.0.0.1", port);
    c.sendRaw(std::string(1 << 20, 'A'));
    EXPECT_EQ(c.readLine(3.0).rfind("ERR TOO_LONG", 0), 0u);
    EXPECT_TRUE(c.closedByServer(3.0));
  }
  {  // slow-loris: a line started and never finished
    LineClient c("127.0.0.1", port);
    c.sendRaw("PI");
    std::this_thread::sleep_for(std::chrono::milliseconds(200));
    c.sendRaw("N");
    EXPECT_EQ(c.readLine(3.0).rfind("ERR TIMEOUT", 0), 0u);
    EXPECT_TRUE(c.closedByServer(3.0));
  }
  for (int i = 0; i < 20; ++i) {  // disconnects mid-message, and right after a blocking request
    LineClient c("127.0.0.1", port);
    c.sendRaw(i % 2 ? "ADJUST\n" : "INPOS 1");
  }
  {  // 100 connections at once: 16 served, the rest refused with a reason
    std::this_thread::sleep_for(std::chrono::milliseconds(200));  // the disconnects above are seen
    std::vector<std::unique_ptr<LineClient>> many;
    int busy = 0;
    for (int i = 0; i < 100; ++i) many.push_back(std::make_unique<LineClient>("127.0.0.1", port));
    std::this_thread::sleep_for(std::chrono::milliseconds(300));
    LineClient* served = nullptr;
    for (auto& c : many) {
      const std::string line = c->readLine(0.05);
      if (line.rfind("ERR BUSY", 0) == 0) {
        ++busy;
      } else if (!served) {
        served = c.get();
      }
    }
    EXPECT_GE(busy, 100 - 16);
    ASSERT_NE(served, nullptr);
    EXPECT_EQ(served->request("PING"), "OK PONG");
  }
  // a bounded random-input run: arbitrary bytes in arbitrary chunks on 20 connections
  std::mt19937 rng(7);
  for (int k = 0; k < 20; ++k) {
    LineClient c("127.0.0.1", port);
    for (int chunk = 0; chunk < 50; ++chunk) {
      std::string bytes(static_cast<size_t>(rng() % 300), '\0');
      for (auto& b : bytes) b = static_cast<char>(rng() % 4 == 0 ? '\n' : rng() % 256);
      if (!c.sendRaw(bytes)) break;
    }
  }
  std::this_thread::sleep_for(std::chrono::milliseconds(300));
  LineClient after("127.0.0.1", port);
  EXPECT_EQ(after.request("PING"), "OK PONG");
  EXPECT_EQ(after.request("ADJUST").rfind("OK ADJUST", 0), 0u);
  const LineServerStats s = bridge.stats();
  EXPECT_GE(s.closed.count("TOO_LONG"), 1u);
  EXPECT_GE(s.closed.count("TIMEOUT"), 1u);
  EXPECT_GE(s.refused, 80u);
}

TEST(RobotBridge, AllowListAndBindingRules) {
  Cell cell;
  RobotBridgeConfig c = testConfig();
  c.server.allow = {"10.1.2.3"};
  RobotBridge bridge(c, cell.callbacks());
  LineClient stranger("127.0.0.1", bridge.port());
  EXPECT_EQ(stranger.readLine(2.0).rfind("ERR NOT_ALLOWED 127.0.0.1", 0), 0u);
  EXPECT_TRUE(stranger.closedByServer(2.0));
  RobotBridgeConfig open = testConfig();
  open.server.bind_address = "0.0.0.0";
  EXPECT_THROW(RobotBridge(open, cell.callbacks()), std::runtime_error);
  open.server.bind_address = "not-an-address";
  open.server.allow = {"10.1.2.3"};
  EXPECT_THROW(RobotBridge(open, cell.callbacks()), std::runtime_error);
}
