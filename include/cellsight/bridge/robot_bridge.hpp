// The robot bridge's line protocol (docs/bridge.md): what a robot controller sends over TCP and
// what it gets back, without ROS on its side. One request per line, printable ASCII, at most
// LineServerConfig::max_line bytes; one answer line per request ("OK …", "ERR <CODE> …"), except
// INPOS, answered when the frame has been captured.
//   HELLO <name>        → OK HELLO cellsight <convention>
//   PING                → OK PONG
//   ADJUST              → OK ADJUST <fixture id> <type> <program> <UCS pose>   (detects now)
//                         ERR NO_FIXTURE … | ERR NO_IMAGE … | ERR NO_TRANSFORM …
//   UCS <program>       → OK UCS <program> <UCS pose> <FRESH|STALE>  (the latest, without detecting)
//   INPOS <seq>         → OK CAPTURED <seq>  (the scanner's stop-and-go handshake), ERR CAPTURE <seq> …
//   QUIT                → OK BYE, then the connection closes
// Poses in the configured convention (robot_conventions.hpp). Ten malformed requests in a row
// close the connection (ERR TOO_MANY_ERRORS).
#pragma once
#include <Eigen/Geometry>
#include <condition_variable>
#include <deque>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <thread>

#include "cellsight/bridge/line_server.hpp"
#include "cellsight/bridge/robot_conventions.hpp"

namespace cellsight {

struct BridgeRequest {
  enum class Kind { kHello, kPing, kAdjust, kUcs, kInPosition, kQuit };
  Kind kind = Kind::kPing;
  std::string name;   ///< HELLO's client name, UCS's program
  uint64_t seq = 0;   ///< INPOS
};

/// Parses one request line. On a malformed line returns false and sets `error` to "<CODE> <reason>"
/// (SYNTAX, UNKNOWN_COMMAND, BAD_ARGUMENT).
bool parseBridgeRequest(const std::string& line, BridgeRequest& request, std::string& error);

/// What the cell answers, supplied by the ROS node (or a test).
struct BridgeAnswer {
  bool ok = false;
  std::string code;        ///< when !ok: NO_FIXTURE, NO_IMAGE, NO_TRANSFORM, UNKNOWN_PROGRAM, CAPTURE, TIMEOUT…
  std::string message;     ///< when !ok: why, for the controller's log
  std::string fixture, type, program;
  Eigen::Isometry3d ucs = Eigen::Isometry3d::Identity();
  bool stale = false;
};

struct BridgeCallbacks {
  std::function<BridgeAnswer()> adjust;                                  ///< may block (seconds)
  std::function<BridgeAnswer(const std::string& program)> ucs;
  std::function<BridgeAnswer(uint64_t seq)> in_position;                 ///< blocks until captured
};

struct RobotBridgeConfig {
  LineServerConfig server;
  PoseConvention convention = PoseConvention::kKuka;
  int max_errors_in_row = 10;
  /// m: a user frame farther from the base (or not finite) is never sent: ERR RANGE instead
  double max_reach = 5.0;
};

/// The protocol over a LineServer. Blocking answers (ADJUST, INPOS) run on a worker thread, one
/// request per client at a time (a second one while the first runs: ERR BUSY).
class RobotBridge {
 public:
  RobotBridge(const RobotBridgeConfig& config, BridgeCallbacks callbacks);
  ~RobotBridge();
  int port() const { return server_->port(); }
  LineServerStats stats() const { return server_->stats(); }

 private:
  void onLine(uint64_t client, const std::string& line);
  void onClosed(uint64_t client);
  void work();

  RobotBridgeConfig config_;
  BridgeCallbacks callbacks_;
  std::mutex mutex_;
  std::condition_variable cv_;
  std::deque<std::pair<uint64_t, BridgeRequest>> jobs_;
  std::map<uint64_t, int> errors_;
  std::map<uint64_t, bool> busy_;
  bool stop_ = false;
  std::unique_ptr<LineServer> server_;
  std::thread worker_;
};

}  // namespace cellsight
