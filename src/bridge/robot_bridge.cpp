#include "cellsight/bridge/robot_bridge.hpp"

#include <algorithm>
#include <cctype>
#include <cmath>
#include <sstream>
#include <vector>

namespace cellsight {
namespace {

BridgeAnswer unavailable(const std::string& why) {
  BridgeAnswer a;
  a.code = "UNAVAILABLE";
  a.message = why;
  return a;
}

/// An answer whose user frame the controller may receive: finite and within `max_reach` of the
/// base; otherwise ERR RANGE, so no value outside the cell ever reaches the robot.
BridgeAnswer withinReach(BridgeAnswer a, double max_reach) {
  if (!a.ok) return a;
  const double d = a.ucs.translation().norm();
  if (a.ucs.matrix().allFinite() && d <= max_reach) return a;
  a.ok = false;
  a.code = "RANGE";
  std::ostringstream why;
  why.precision(3);
  why << "the user frame of " << a.program << " is not sent: it lies " << (std::isfinite(d) ? d : -1.0)
      << " m from the base (beyond " << max_reach << " m, or not finite): check the fixture registry's ucs";
  a.message = why.str();
  return a;
}

bool nameOk(const std::string& s) {
  if (s.empty() || s.size() > 64) return false;
  return std::all_of(s.begin(), s.end(), [](char c) {
    return std::isalnum(static_cast<unsigned char>(c)) || c == '_' || c == '-' || c == '.';
  });
}

}  // namespace

bool parseBridgeRequest(const std::string& line, BridgeRequest& r, std::string& error) {
  for (char c : line) {
    if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) > 0x7e) {
      error = "SYNTAX the request holds a byte that is not printable ASCII";
      return false;
    }
  }
  std::istringstream in(line);
  std::vector<std::string> t;
  std::string w;
  while (in >> w) t.push_back(w);
  if (t.empty()) {
    error = "SYNTAX empty request";
    return false;
  }
  std::string cmd = t[0];
  std::transform(cmd.begin(), cmd.end(), cmd.begin(), [](unsigned char c) { return static_cast<char>(std::toupper(c)); });
  auto args = [&](size_t n) {
    if (t.size() == n + 1) return true;
    error = "BAD_ARGUMENT " + cmd + " takes " + std::to_string(n) + " argument" + (n == 1 ? "" : "s") + ", got " +
            std::to_string(t.size() - 1);
    return false;
  };
  if (cmd == "PING" || cmd == "ADJUST" || cmd == "QUIT") {
    if (!args(0)) return false;
    r.kind = cmd == "PING" ? BridgeRequest::Kind::kPing : cmd == "ADJUST" ? BridgeRequest::Kind::kAdjust : BridgeRequest::Kind::kQuit;
    return true;
  }
  if (cmd == "HELLO" || cmd == "UCS") {
    if (!args(1)) return false;
    if (!nameOk(t[1])) {
      error = "BAD_ARGUMENT '" + t[1].substr(0, 64) + "' is not a name (letters, digits, _ - ., at most 64)";
      return false;
    }
    r.kind = cmd == "HELLO" ? BridgeRequest::Kind::kHello : BridgeRequest::Kind::kUcs;
    r.name = t[1];
    return true;
  }
  if (cmd == "INPOS") {
    if (!args(1)) return false;
    if (t[1].size() > 10 || t[1].find_first_not_of("0123456789") != std::string::npos) {
      error = "BAD_ARGUMENT the sequence number must be 1 to 10 decimal digits";
      return false;
    }
    r.kind = BridgeRequest::Kind::kInPosition;
    r.seq = std::stoull(t[1]);
    return true;
  }
  error = "UNKNOWN_COMMAND '" + cmd.substr(0, 32) + "' (HELLO, PING, ADJUST, UCS, INPOS, QUIT)";
  return false;
}

RobotBridge::RobotBridge(const RobotBridgeConfig& config, BridgeCallbacks callbacks)
    : config_(config), callbacks_(std::move(callbacks)) {
  server_ = std::make_unique<LineServer>(
      config_.server, [this](uint64_t c, const std::string& l) { onLine(c, l); }, [this](uint64_t c) { onClosed(c); });
  worker_ = std::thread([this] { work(); });
  server_->start();  // lines reach onLine only now, with server_ and the worker in place
}

RobotBridge::~RobotBridge() {
  server_->stop();  // no more lines; the server object stays for the worker's last send()
  {
    std::lock_guard<std::mutex> lock(mutex_);
    stop_ = true;
  }
  cv_.notify_all();
  if (worker_.joinable()) worker_.join();
  server_.reset();
}

void RobotBridge::onClosed(uint64_t client) {
  std::lock_guard<std::mutex> lock(mutex_);
  errors_.erase(client);
  busy_.erase(client);
}

void RobotBridge::onLine(uint64_t client, const std::string& line) {
  BridgeRequest req;
  std::string error;
  if (!parseBridgeRequest(line, req, error)) {
    int errors = 0;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      errors = ++errors_[client];
    }
    if (errors >= config_.max_errors_in_row) {
      server_->close(client, "TOO_MANY_ERRORS", std::to_string(errors) + " malformed requests in a row; closing");
    } else {
      server_->send(client, "ERR " + error);
    }
    return;
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    errors_[client] = 0;
  }
  switch (req.kind) {
    case BridgeRequest::Kind::kHello:
      server_->send(client, "OK HELLO cellsight " + poseConventionName(config_.convention));
      return;
    case BridgeRequest::Kind::kPing:
      server_->send(client, "OK PONG");
      return;
    case BridgeRequest::Kind::kQuit:
      server_->send(client, "OK BYE");
      server_->close(client, "", "");
      return;
    default:
      break;
  }
  {
    std::lock_guard<std::mutex> lock(mutex_);
    if (busy_[client]) {
      server_->send(client, "ERR BUSY the previous request is still running");
      return;
    }
    busy_[client] = true;
    jobs_.emplace_back(client, req);
  }
  cv_.notify_one();
}

void RobotBridge::work() {
  for (;;) {
    std::pair<uint64_t, BridgeRequest> job;
    {
      std::unique_lock<std::mutex> lock(mutex_);
      cv_.wait(lock, [&] { return stop_ || !jobs_.empty(); });
      if (stop_) return;
      job = jobs_.front();
      jobs_.pop_front();
      if (!busy_.count(job.first)) continue;  // the client has gone: nothing is run for it
    }
    const auto& [client, req] = job;
    BridgeAnswer a;
    std::string reply;
    try {
      switch (req.kind) {
        case BridgeRequest::Kind::kAdjust:
          a = withinReach(callbacks_.adjust ? callbacks_.adjust() : unavailable("no fixture detection in this cell"),
                          config_.max_reach);
          reply = a.ok ? "OK ADJUST " + a.fixture + " " + a.type + " " + a.program + " " + formatRobotPose(a.ucs, config_.convention)
                       : "ERR " + a.code + " " + a.message;
          break;
        case BridgeRequest::Kind::kUcs:
          a = withinReach(callbacks_.ucs ? callbacks_.ucs(req.name) : unavailable("no fixture detection in this cell"),
                          config_.max_reach);
          reply = a.ok ? "OK UCS " + a.program + " " + formatRobotPose(a.ucs, config_.convention) + (a.stale ? " STALE" : " FRESH")
                       : "ERR " + a.code + " " + a.message;
          break;
        case BridgeRequest::Kind::kInPosition:
          a = callbacks_.in_position ? callbacks_.in_position(req.seq)
                                     : unavailable("no scanner in this cell");
          reply = a.ok ? "OK CAPTURED " + std::to_string(req.seq)
                       : "ERR " + (a.code.empty() ? std::string("CAPTURE") : a.code) + " " + std::to_string(req.seq) + " " + a.message;
          break;
        default:
          break;
      }
    } catch (const std::exception& e) {
      reply = std::string("ERR INTERNAL ") + e.what();
    }
    // one line, printable, whatever the callbacks put in their messages
    for (char& c : reply) {
      if (static_cast<unsigned char>(c) < 0x20 || static_cast<unsigned char>(c) > 0x7e) c = ' ';
    }
    // the reply queued and the client free again in one step: a controller that sends its next
    // request as soon as the reply arrives must not find the previous one still "running"
    // (lock order as in onLine: this mutex, then the server's)
    std::lock_guard<std::mutex> lock(mutex_);
    server_->send(client, reply);
    if (busy_.count(client)) busy_[client] = false;
  }
}

}  // namespace cellsight
