// robot_bridge: the cell as a robot controller sees it, over TCP without ROS on its side
// (protocol: include/cellsight/bridge/robot_bridge.hpp, docs/bridge.md).
//   ADJUST       calls qr_frame_adjustment's ~adjust service (detect now), answers the program and its UCS
//   UCS <prog>   the latest user frame of that program from qr_frame_adjustment's ~fixtures
//   INPOS <seq>  publishes io/in_position and answers when io/capture_done comes (stop-and-go)
// Bound to loopback unless ~bind_address is set, and then only with an ~allow list.
#include <ros/ros.h>
#include <std_msgs/Bool.h>

#include <chrono>
#include <condition_variable>
#include <atomic>
#include <future>
#include <thread>
#include <tuple>
#include <mutex>

#include "cellsight/AdjustFixtures.h"
#include "cellsight/FixtureArray.h"
#include "cellsight/bridge/robot_bridge.hpp"
#include "cellsight_ros/conversions.hpp"
#include "cellsight_ros/diagnostics.hpp"
#include "cellsight_ros/node.hpp"
#include "cellsight_ros/params.hpp"

namespace {

class RobotBridgeNode {
 public:
  RobotBridgeNode(ros::NodeHandle& nh, ros::NodeHandle& pnh) : diag_(nh, pnh, "robot_bridge", "requests") {
    cellsight::RobotBridgeConfig c;
    std::string convention = "kuka";
    int port = 30300, max_line = 256;
    cellsight_ros::param(pnh, "port", port);
    cellsight_ros::param(pnh, "bind_address", c.server.bind_address);
    cellsight_ros::param(pnh, "allow", c.server.allow);
    cellsight_ros::param(pnh, "convention", convention);
    cellsight_ros::param(pnh, "max_line", max_line);
    cellsight_ros::param(pnh, "max_clients", c.server.max_clients);
    cellsight_ros::param(pnh, "line_timeout", c.server.line_timeout);
    cellsight_ros::param(pnh, "idle_timeout", c.server.idle_timeout);
    cellsight_ros::param(pnh, "adjust_timeout", adjust_timeout_);
    cellsight_ros::param(pnh, "capture_timeout", capture_timeout_);
    std::string adjust_service = "qr_frame_adjustment/adjust", fixtures_topic = "qr_frame_adjustment/fixtures";
    cellsight_ros::param(pnh, "adjust_service", adjust_service);
    cellsight_ros::param(pnh, "fixtures_topic", fixtures_topic);
    if (port < 0 || port > 65535) throw std::runtime_error("~port must be 0..65535, not " + std::to_string(port));
    if (max_line < 16 || max_line > 65536) throw std::runtime_error("~max_line must be 16..65536");
    cellsight_ros::param(pnh, "max_reach", c.max_reach);
    // nonsensical values refuse the start (a negative idle timeout closed every connection)
    for (const auto& [name, v] : {std::pair<const char*, double>{"line_timeout", c.server.line_timeout},
                                  {"idle_timeout", c.server.idle_timeout}, {"adjust_timeout", adjust_timeout_},
                                  {"capture_timeout", capture_timeout_}})
      if (!(v > 0 && v <= 3600)) throw std::runtime_error(std::string("~") + name + " must lie in (0, 3600] s, not " + std::to_string(v));
    if (!(c.max_reach > 0 && c.max_reach <= 100)) throw std::runtime_error("~max_reach must lie in (0, 100] m");
    if (c.server.max_clients < 1 || c.server.max_clients > 1024) throw std::runtime_error("~max_clients must be 1..1024");
    c.server.port = port;
    c.server.max_line = static_cast<size_t>(max_line);
    c.convention = cellsight::parsePoseConvention(convention);
    adjust_ = nh.serviceClient<cellsight::AdjustFixtures>(adjust_service);
    fixtures_sub_ = nh.subscribe(fixtures_topic, 1, &RobotBridgeNode::onFixtures, this);
    in_position_pub_ = nh.advertise<std_msgs::Bool>("io/in_position", 10);
    capture_done_sub_ = nh.subscribe("io/capture_done", 10, &RobotBridgeNode::onCaptureDone, this);
    cellsight::BridgeCallbacks cb;
    cb.adjust = [this] { return adjust(); };
    cb.ucs = [this](const std::string& p) { return ucs(p); };
    cb.in_position = [this](uint64_t seq) { return inPosition(seq); };
    bridge_ = std::make_unique<cellsight::RobotBridge>(c, cb);
    pnh.setParam("bound_port", bridge_->port());  // the port actually bound (~port 0: any free one)
    diag_.addValue("connections", [this] { return std::to_string(bridge_->stats().clients); });
    ROS_INFO("robot_bridge: listening on %s:%d (%s poses, %zu allowed addresses%s)", c.server.bind_address.c_str(),
             bridge_->port(), convention.c_str(), c.server.allow.size(), c.server.allow.empty() ? ": loopback only" : "");
  }

 private:
  cellsight::BridgeAnswer adjust() {
    cellsight::BridgeAnswer a;
    cellsight::AdjustFixtures srv;
    srv.request.timeout = adjust_timeout_;
    // roscpp service calls have no timeout: the call runs on a thread of its own, so a hung
    // qr_frame_adjustment costs this request a timeout, not the bridge its worker
    // one such call at a time: a hung service costs one thread, not one per request
    if (adjust_calls_->load() > 0) {
      a.code = "BUSY";
      a.message = "the fixture service " + adjust_.getService() + " has not answered the last ADJUST yet";
      failedAdjust();
      return a;
    }
    auto result = std::make_shared<std::promise<std::pair<bool, cellsight::AdjustFixtures>>>();
    auto answer = result->get_future();
    ++*adjust_calls_;
    std::thread([client = adjust_, srv, result, calls = adjust_calls_]() mutable {
      const bool ok = client.call(srv);
      result->set_value({ok, srv});
      --*calls;
    }).detach();
    if (answer.wait_for(std::chrono::duration<double>(adjust_timeout_ + 5.0)) != std::future_status::ready) {
      a.code = "TIMEOUT";
      a.message = "the fixture service " + adjust_.getService() + " did not answer within " +
                  std::to_string(adjust_timeout_ + 5.0) + " s";
      diag_.dropped("adjust service timed out");
      failedAdjust();
      return a;
    }
    bool called = false;
    std::tie(called, srv) = answer.get();
    if (!called) {
      a.code = "UNAVAILABLE";
      a.message = "the fixture service " + adjust_.getService() + " did not answer (is qr_frame_adjustment running?)";
      diag_.dropped("adjust service unavailable");
      failedAdjust();
      return a;
    }
    const auto& r = srv.response;
    if (r.status != r.OK || r.fixtures.empty()) {
      a.code = r.status == r.NO_IMAGE       ? "NO_IMAGE"
               : r.status == r.NO_TRANSFORM ? "NO_TRANSFORM"
               : r.status == r.BUSY         ? "BUSY"
                                            : "NO_FIXTURE";
      a.message = r.message;
      diag_.processed();
      if (r.status != r.NO_FIXTURE) failedAdjust();
      return a;
    }
    const auto& f = r.fixtures.front();
    a.ok = true;
    a.fixture = f.id;
    a.type = f.type;
    a.program = f.program;
    a.ucs = cellsight_ros::fromPoseMsg(f.ucs);
    diag_.processed();
    return a;
  }

  cellsight::BridgeAnswer ucs(const std::string& program) {
    cellsight::BridgeAnswer a;
    std::lock_guard<std::mutex> lock(mutex_);
    for (const auto& f : fixtures_.fixtures) {
      if (f.program != program) continue;
      a.ok = true;
      a.fixture = f.id;
      a.type = f.type;
      a.program = f.program;
      a.ucs = cellsight_ros::fromPoseMsg(f.ucs);
      a.stale = f.stale || fixtures_.header.stamp <= adjust_failed_at_;
      return a;
    }
    a.code = "UNKNOWN_PROGRAM";
    a.message = "no fixture seen runs program " + program;
    return a;
  }

  cellsight::BridgeAnswer inPosition(uint64_t seq) {
    cellsight::BridgeAnswer a;
    std::unique_lock<std::mutex> lock(mutex_);
    const uint64_t before = captures_;
    waiting_ = true;  // a capture_done counts only while a request waits (not a latched old one)
    std_msgs::Bool msg;
    msg.data = true;
    in_position_pub_.publish(msg);
    const bool done = cv_.wait_for(lock, std::chrono::duration<double>(capture_timeout_), [&] { return captures_ > before; });
    waiting_ = false;
    if (!done) {
      a.code = "CAPTURE";
      a.message = "no io/capture_done within " + std::to_string(capture_timeout_) + " s (is camera_trigger running?)";
      ROS_WARN("robot_bridge: INPOS %lu: %s", static_cast<unsigned long>(seq), a.message.c_str());
      return a;
    }
    a.ok = true;
    return a;
  }

  void onFixtures(const cellsight::FixtureArray& msg) {
    std::lock_guard<std::mutex> lock(mutex_);
    fixtures_ = msg;
  }

  /// The fixtures known so far are reported STALE until an image newer than this failure.
  void failedAdjust() {
    std::lock_guard<std::mutex> lock(mutex_);
    adjust_failed_at_ = ros::Time::now();
  }

  void onCaptureDone(const std_msgs::Bool& msg) {
    if (!msg.data) return;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      if (!waiting_) return;
      ++captures_;
    }
    cv_.notify_all();
  }

  cellsight_ros::NodeDiagnostics diag_;
  ros::ServiceClient adjust_;
  ros::Subscriber fixtures_sub_, capture_done_sub_;
  ros::Publisher in_position_pub_;
  double adjust_timeout_ = 5.0, capture_timeout_ = 10.0;
  std::mutex mutex_;
  std::condition_variable cv_;
  uint64_t captures_ = 0;
  bool waiting_ = false;
  cellsight::FixtureArray fixtures_;
  ros::Time adjust_failed_at_;  // the latest failed ADJUST (zero: none)
  std::shared_ptr<std::atomic<int>> adjust_calls_ = std::make_shared<std::atomic<int>>(0);  // fixture service calls running
  std::unique_ptr<cellsight::RobotBridge> bridge_;
};

}  // namespace

CELLSIGHT_NODE(RobotBridgeNode, "robot_bridge", 2)
