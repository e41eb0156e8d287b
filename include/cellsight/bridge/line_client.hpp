// A blocking line client for the robot bridge: what a controller does, for the simulated
// controller (cellsight_robot_client) and the tests.
#pragma once
#include <string>

namespace cellsight {

class LineClient {
 public:
  /// Connects (IPv4 host, port) within `timeout` s; throws std::runtime_error naming the cause.
  LineClient(const std::string& host, int port, double timeout = 5.0);
  ~LineClient();
  LineClient(const LineClient&) = delete;
  LineClient& operator=(const LineClient&) = delete;

  /// Sends raw bytes (no newline added); false when the connection is gone.
  bool sendRaw(const std::string& bytes);
  bool sendLine(const std::string& line) { return sendRaw(line + "\n"); }
  /// The next line (without "\n"); empty with `closed` set when the server closed the
  /// connection, empty with `closed` unset on a timeout.
  std::string readLine(double timeout, bool* closed = nullptr);
  /// sendLine + readLine.
  std::string request(const std::string& line, double timeout = 10.0);
  /// True when the server has closed the connection (waits up to `timeout` s for it).
  bool closedByServer(double timeout);

 private:
  int fd_ = -1;
  std::string buffer_;
};

}  // namespace cellsight
