// A TCP server for newline-terminated text lines, built to face a shop floor network: one poll()
// thread, bound to loopback unless configured, an allow-list of client addresses, a line length
// limit, a deadline for a started line (slow-loris) and for an idle connection, a connection limit
// and an output limit (a client that does not read). Every refusal is answered with one line
// "ERR <CODE> <reason>" before the connection is closed.
#pragma once
#include <atomic>
#include <cstdint>
#include <functional>
#include <map>
#include <mutex>
#include <string>
#include <thread>
#include <vector>

namespace cellsight {

struct LineServerConfig {
  std::string bind_address = "127.0.0.1";  ///< IPv4; a non-loopback address needs `allow`
  int port = 0;                            ///< 0: any free port (see LineServer::port())
  std::vector<std::string> allow;          ///< client IPv4 addresses; empty: any (loopback binding only)
  size_t max_line = 256;                   ///< bytes without the newline
  int max_clients = 16;
  double line_timeout = 5.0;               ///< s from a line's first byte to its newline
  double idle_timeout = 300.0;             ///< s without a complete line
  size_t max_output = 64 * 1024;           ///< bytes queued for a client that does not read
};

struct LineServerStats {
  uint64_t accepted = 0, refused = 0, lines = 0;
  std::map<std::string, uint64_t> closed;  ///< reason → count (peer, TOO_LONG, TIMEOUT, …)
  int clients = 0;
};

class LineServer {
 public:
  /// Called on the server thread for each complete line (without "\n" or "\r\n"); reply with
  /// send() from there or from any other thread.
  using Handler = std::function<void(uint64_t client, const std::string& line)>;
  /// Called when a client's connection ends (any reason).
  using Closed = std::function<void(uint64_t client)>;

  /// Binds and listens (connections wait in the backlog until start()); throws
  /// std::runtime_error naming the cause (address in use, a public address without an
  /// allow-list, a bad address).
  LineServer(const LineServerConfig& config, Handler handler, Closed closed = {});
  ~LineServer();
  /// Starts the serving thread; call once, after whatever the handler uses is ready.
  void start();
  /// Stops serving and joins the thread (no handler call after it returns); the destructor
  /// calls it.
  void stop();
  LineServer(const LineServer&) = delete;
  LineServer& operator=(const LineServer&) = delete;

  int port() const { return port_; }
  /// Queues `line` + "\n" for the client (thread-safe); ignored when the client is gone.
  void send(uint64_t client, const std::string& line);
  /// Sends "ERR <code> <reason>" (nothing when `code` is empty) and closes the connection once
  /// everything queued is written; no further line of the client reaches the handler.
  void close(uint64_t client, const std::string& code, const std::string& reason);
  LineServerStats stats() const;

 private:
  struct Client;
  void run();
  void wake();
  void drop(uint64_t id, const std::string& why);

  LineServerConfig config_;
  Handler handler_;
  Closed closed_;
  int listen_fd_ = -1, wake_[2] = {-1, -1}, port_ = 0;
  std::atomic<bool> stop_{false};
  mutable std::mutex mutex_;
  std::map<uint64_t, Client*> clients_;
  uint64_t next_id_ = 1;
  LineServerStats stats_;
  std::thread thread_;
};

}  // namespace cellsight
