#include "cellsight/bridge/line_server.hpp"

#include <arpa/inet.h>
#include <fcntl.h>
#include <netinet/in.h>
#include <netinet/tcp.h>
#include <poll.h>
#include <sys/socket.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstring>
#include <stdexcept>

namespace cellsight {
namespace {

double now() {
  return std::chrono::duration<double>(std::chrono::steady_clock::now().time_since_epoch()).count();
}

void nonBlocking(int fd) { ::fcntl(fd, F_SETFL, ::fcntl(fd, F_GETFL, 0) | O_NONBLOCK); }

bool loopback(const std::string& address) { return address.rfind("127.", 0) == 0; }

// best effort, for refusals before a client exists
void writeNow(int fd, const std::string& text) {
  const ssize_t n = ::send(fd, text.data(), text.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
  (void)n;
}

}  // namespace

struct LineServer::Client {
  int fd = -1;
  std::string address;
  std::string in, out;
  double connected = 0, line_started = 0, last_line = 0, closing_since = 0;
  bool closing = false;
  std::string close_reason;
};

LineServer::LineServer(const LineServerConfig& config, Handler handler, Closed closed)
    : config_(config), handler_(std::move(handler)), closed_(std::move(closed)) {
  if (!loopback(config_.bind_address) && config_.allow.empty()) {
    throw std::runtime_error("robot bridge: binding to " + config_.bind_address +
                             " needs an allow-list of controller addresses (parameter allow)");
  }
  if (config_.max_line == 0 || config_.max_clients <= 0) throw std::runtime_error("robot bridge: max_line and max_clients must be positive");
  sockaddr_in addr{};
  addr.sin_family = AF_INET;
  addr.sin_port = htons(static_cast<uint16_t>(config_.port));
  if (::inet_pton(AF_INET, config_.bind_address.c_str(), &addr.sin_addr) != 1) {
    throw std::runtime_error("robot bridge: '" + config_.bind_address + "' is not an IPv4 address");
  }
  listen_fd_ = ::socket(AF_INET, SOCK_STREAM | SOCK_CLOEXEC, 0);
  if (listen_fd_ < 0) throw std::runtime_error(std::string("robot bridge: socket: ") + std::strerror(errno));
  const int one = 1;
  ::setsockopt(listen_fd_, SOL_SOCKET, SO_REUSEADDR, &one, sizeof(one));
  if (::bind(listen_fd_, reinterpret_cast<sockaddr*>(&addr), sizeof(addr)) != 0 || ::listen(listen_fd_, 32) != 0) {
    const std::string why = std::strerror(errno);
    ::close(listen_fd_);
    throw std::runtime_error("robot bridge: cannot listen on " + config_.bind_address + ":" + std::to_string(config_.port) +
                             ": " + why);
  }
  socklen_t len = sizeof(addr);
  ::getsockname(listen_fd_, reinterpret_cast<sockaddr*>(&addr), &len);
  port_ = ntohs(addr.sin_port);
  nonBlocking(listen_fd_);
  if (::pipe2(wake_, O_CLOEXEC | O_NONBLOCK) != 0) {
    ::close(listen_fd_);
    throw std::runtime_error(std::string("robot bridge: pipe: ") + std::strerror(errno));
  }
}

void LineServer::start() {
  if (!thread_.joinable() && !stop_) thread_ = std::thread([this] { run(); });
}

void LineServer::stop() {
  stop_ = true;
  wake();
  if (thread_.joinable()) thread_.join();
}

LineServer::~LineServer() {
  stop();
  for (auto& [id, c] : clients_) {
    ::close(c->fd);
    delete c;
  }
  ::close(listen_fd_);
  ::close(wake_[0]);
  ::close(wake_[1]);
}

void LineServer::wake() {
  const char b = 1;
  const ssize_t n = ::write(wake_[1], &b, 1);
  (void)n;
}

void LineServer::send(uint64_t id, const std::string& line) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = clients_.find(id);
    if (it == clients_.end() || it->second->closing) return;
    it->second->out += line;
    it->second->out += '\n';
  }
  wake();
}

void LineServer::close(uint64_t id, const std::string& code, const std::string& reason) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = clients_.find(id);
    if (it == clients_.end() || it->second->closing) return;
    if (!code.empty()) it->second->out += "ERR " + code + " " + reason + "\n";
    it->second->closing = true;
    it->second->closing_since = now();
    it->second->close_reason = code;
  }
  wake();
}

LineServerStats LineServer::stats() const {
  std::lock_guard<std::mutex> lock(mutex_);
  LineServerStats s = stats_;
  s.clients = static_cast<int>(clients_.size());
  return s;
}

void LineServer::drop(uint64_t id, const std::string& why) {
  {
    std::lock_guard<std::mutex> lock(mutex_);
    const auto it = clients_.find(id);
    if (it == clients_.end()) return;
    ::close(it->second->fd);
    delete it->second;
    clients_.erase(it);
    ++stats_.closed[why];
  }
  if (closed_) closed_(id);
}

void LineServer::run() {
  std::vector<pollfd> fds;
  std::vector<uint64_t> ids;
  char buf[4096];
  double listen_paused_until = 0;  // out of file descriptors: the listener rests a moment
  while (!stop_) {
    fds.clear();
    ids.clear();
    fds.push_back({listen_fd_, static_cast<short>(now() < listen_paused_until ? 0 : POLLIN), 0});
    fds.push_back({wake_[0], POLLIN, 0});
    {
      std::lock_guard<std::mutex> lock(mutex_);
      for (const auto& [id, c] : clients_) {
        fds.push_back({c->fd, static_cast<short>((c->closing ? 0 : POLLIN) | (c->out.empty() ? 0 : POLLOUT)), 0});
        ids.push_back(id);
      }
    }
    if (::poll(fds.data(), fds.size(), 100) < 0 && errno != EINTR) break;
    if (fds[1].revents & POLLIN) {
      while (::read(wake_[0], buf, sizeof(buf)) > 0) {
      }
    }
    if (fds[0].revents & POLLIN) {
      for (;;) {
        sockaddr_in peer{};
        socklen_t len = sizeof(peer);
        const int fd = ::accept4(listen_fd_, reinterpret_cast<sockaddr*>(&peer), &len, SOCK_CLOEXEC | SOCK_NONBLOCK);
        if (fd < 0) {
          if (errno == EMFILE || errno == ENFILE || errno == ENOBUFS || errno == ENOMEM) listen_paused_until = now() + 0.1;
          break;
        }
        char ip[INET_ADDRSTRLEN] = {0};
        ::inet_ntop(AF_INET, &peer.sin_addr, ip, sizeof(ip));
        const std::string address = ip;
        std::lock_guard<std::mutex> lock(mutex_);
        if (!config_.allow.empty() && std::find(config_.allow.begin(), config_.allow.end(), address) == config_.allow.end()) {
          writeNow(fd, "ERR NOT_ALLOWED " + address + " is not in the bridge's allow-list\n");
          ::close(fd);
          ++stats_.refused;
          continue;
        }
        if (static_cast<int>(clients_.size()) >= config_.max_clients) {
          writeNow(fd, "ERR BUSY " + std::to_string(config_.max_clients) + " connections already open\n");
          ::close(fd);
          ++stats_.refused;
          continue;
        }
        const int one = 1;
        ::setsockopt(fd, IPPROTO_TCP, TCP_NODELAY, &one, sizeof(one));
        auto* c = new Client;
        c->fd = fd;
        c->address = address;
        c->connected = c->last_line = now();
        clients_[next_id_++] = c;
        ++stats_.accepted;
      }
    }
    for (size_t k = 2; k < fds.size(); ++k) {
      const uint64_t id = ids[k - 2];
      const short ev = fds[k].revents;
      Client* c = nullptr;
      {
        std::lock_guard<std::mutex> lock(mutex_);
        const auto it = clients_.find(id);
        if (it == clients_.end()) continue;
        c = it->second;
      }
      if (ev & POLLOUT) {
        std::unique_lock<std::mutex> lock(mutex_);
        const ssize_t n = ::send(c->fd, c->out.data(), c->out.size(), MSG_NOSIGNAL | MSG_DONTWAIT);
        const int send_errno = errno;
        if (n > 0) c->out.erase(0, static_cast<size_t>(n));
        const bool done = c->closing && c->out.empty();
        const std::string reason = c->close_reason;
        lock.unlock();
        if (n < 0 && send_errno != EAGAIN && send_errno != EWOULDBLOCK) {
          drop(id, "write error");
          continue;
        }
        if (done) {
          drop(id, reason);
          continue;
        }
      }
      if (ev & POLLIN) {
        const ssize_t n = ::recv(c->fd, buf, sizeof(buf), 0);
        if (n == 0) {
          drop(id, "peer closed");
          continue;
        }
        if (n < 0) {
          if (errno != EAGAIN && errno != EWOULDBLOCK) drop(id, "read error");
          continue;
        }
        std::vector<std::string> lines;
        bool too_long = false;
        {
          std::lock_guard<std::mutex> lock(mutex_);
          if (c->closing) continue;
          if (c->in.empty()) c->line_started = now();
          c->in.append(buf, static_cast<size_t>(n));
          size_t pos;
          while ((pos = c->in.find('\n')) != std::string::npos) {
            std::string line = c->in.substr(0, pos);
            if (!line.empty() && line.back() == '\r') line.pop_back();
            c->in.erase(0, pos + 1);
            if (line.size() > config_.max_line) {
              too_long = true;
              break;
            }
            lines.push_back(std::move(line));
            c->last_line = c->line_started = now();
          }
          too_long = too_long || c->in.size() > config_.max_line;
          stats_.lines += lines.size();
        }
        for (const auto& line : lines) {
          {
            std::lock_guard<std::mutex> lock(mutex_);
            const auto it = clients_.find(id);
            if (it == clients_.end() || it->second->closing) break;  // QUIT, TOO_MANY_ERRORS: no more lines
          }
          handler_(id, line);
        }
        if (too_long) {
          close(id, "TOO_LONG", "a line is longer than " + std::to_string(config_.max_line) + " bytes; closing");
          std::lock_guard<std::mutex> lock(mutex_);
          const auto it = clients_.find(id);
          if (it != clients_.end()) it->second->in.clear();
        }
      }
      if (ev & (POLLERR | POLLHUP | POLLNVAL)) {
        if (!(ev & POLLIN)) drop(id, "connection error");
      }
    }
    // deadlines and output limits
    const double t = now();
    std::vector<std::pair<uint64_t, std::pair<std::string, std::string>>> to_close;
    std::vector<std::pair<uint64_t, std::string>> to_drop;
    {
      std::lock_guard<std::mutex> lock(mutex_);
      for (const auto& [id, c] : clients_) {
        if (c->closing) {
          if (t - c->closing_since > 2.0) to_drop.emplace_back(id, c->close_reason);
        } else if (c->out.size() > config_.max_output) {
          to_drop.emplace_back(id, "SLOW_READER");
        } else if (!c->in.empty() && t - c->line_started > config_.line_timeout) {
          to_close.push_back({id, {"TIMEOUT", "a line was not finished within " + std::to_string(config_.line_timeout) + " s; closing"}});
        } else if (t - c->last_line > config_.idle_timeout) {
          to_close.push_back({id, {"IDLE", "no request for " + std::to_string(config_.idle_timeout) + " s; closing"}});
        }
      }
    }
    for (const auto& [id, why] : to_drop) drop(id, why);
    for (const auto& [id, cr] : to_close) close(id, cr.first, cr.second);
  }
}

}  // namespace cellsight
