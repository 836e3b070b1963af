#pragma once

#include <hiredis/hiredis.h>
#include <netinet/in.h>
#include <sys/socket.h>

#include <chrono>
#include <filesystem>
#include <fstream>
#include <optional>
#include <sstream>
#include <stdexcept>
#include <string>
#include <thread>
#include <utility>
#include <vector>

#include "optimus/support/child_process.hpp"

#ifndef PRIME_REDIS_SERVER
#define PRIME_REDIS_SERVER "redis-server"
#endif

namespace prime::test {

// A private redis-server (the Debian package) for a test: a free loopback
// port and a Unix socket in a fresh directory, persistence off (--save ""
// --appendonly no), stopped and cleaned up when the object goes. It can be
// stopped and started again on the same port, to test what a restart does.
// The server is killed when the thread that made (or restarted) it ends
// (ChildProcess): make it on a thread that outlives its use.
class RedisServer {
 public:
  struct Config {
    std::vector<std::string> bind{"127.0.0.1"};  // addresses to listen on; the URL uses the first
    std::vector<std::string> extra{};            // more redis-server arguments (--requirepass x, --user ...)
  };

  RedisServer() : RedisServer{Config{}} {}
  explicit RedisServer(Config config) : config_{std::move(config)} {
    char dir[] = "/tmp/prime-redis-XXXXXX";
    if (!::mkdtemp(dir)) throw std::runtime_error{"RedisServer: mkdtemp failed"};
    dir_ = dir;
    for (int attempt = 0;; ++attempt) {
      port_ = free_port();
      try {
        start();
        return;
      } catch (const std::exception&) {
        if (attempt == 4) {
          std::filesystem::remove_all(dir_);
          throw;
        }
      }
    }
  }
  RedisServer(const RedisServer&) = delete;
  RedisServer& operator=(const RedisServer&) = delete;
  ~RedisServer() {
    stop();
    std::error_code ignored;
    std::filesystem::remove_all(dir_, ignored);
  }

  [[nodiscard]] int port() const noexcept { return port_; }
  [[nodiscard]] std::string url() const { return "tcp://" + config_.bind.front() + ":" + std::to_string(port_); }
  [[nodiscard]] std::string unix_url() const { return "unix://" + socket_path(); }
  [[nodiscard]] bool running() const { return process_ && process_->running(); }

  // Starts the server (again, on the same port) and waits until it answers PING.
  void start() {
    if (running()) return;
    std::vector<std::string> argv{PRIME_REDIS_SERVER, "--port", std::to_string(port_), "--bind"};
    argv.insert(argv.end(), config_.bind.begin(), config_.bind.end());
    for (std::string arg : {"--save", "", "--appendonly", "no", "--protected-mode", "no", "--daemonize", "no",
                            "--loglevel", "warning"})
      argv.push_back(arg);
    argv.insert(argv.end(), {"--dir", dir_.string(), "--logfile", log_path(), "--unixsocket", socket_path(),
                             "--unixsocketperm", "700"});
    argv.insert(argv.end(), config_.extra.begin(), config_.extra.end());
    process_.emplace(argv);
    const auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds{20};
    while (!answers()) {
      if (std::chrono::steady_clock::now() > deadline || !alive()) {
        process_.reset();
        throw std::runtime_error{"redis-server on port " + std::to_string(port_) + " did not start: " + log_tail()};
      }
      std::this_thread::sleep_for(std::chrono::milliseconds{5});  // polling for a port to open
    }
  }

  // Stops it at once (SIGKILL: as a crash would), without cleaning anything.
  void kill() {
    if (process_) process_->kill();
    process_.reset();
  }

  // Stops it the orderly way.
  void stop() {
    if (process_) process_->stop();
    process_.reset();
  }

 private:
  static int free_port() {
    const int fd = ::socket(AF_INET, SOCK_STREAM, 0);
    sockaddr_in addr{};
    addr.sin_family = AF_INET;
    addr.sin_addr.s_addr = htonl(INADDR_LOOPBACK);
    addr.sin_port = 0;
    socklen_t len = sizeof addr;
    if (::bind(fd, reinterpret_cast<sockaddr*>(&addr), sizeof addr) != 0 ||
        ::getsockname(fd, reinterpret_cast<sockaddr*>(&addr), &len) != 0) {
      ::close(fd);
      throw std::runtime_error{"RedisServer: no free port"};
    }
    ::close(fd);
    return ntohs(addr.sin_port);
  }

  [[nodiscard]] std::string socket_path() const { return (dir_ / "redis.sock").string(); }
  [[nodiscard]] std::string log_path() const { return (dir_ / "redis.log").string(); }

  bool alive() {
    int status = 0;
    return process_ && ::waitpid(process_->pid(), &status, WNOHANG) == 0;
  }

  bool answers() const {
    timeval tv{0, 200'000};
    redisContext* c = redisConnectUnixWithTimeout(socket_path().c_str(), tv);
    bool ok = false;
    if (c && !c->err) {
      auto* reply = static_cast<redisReply*>(redisCommand(c, "PING"));
      // A server that wants a password answers NOAUTH: it is up all the same.
      ok = reply && (reply->type == REDIS_REPLY_STATUS || reply->type == REDIS_REPLY_ERROR);
      if (reply) freeReplyObject(reply);
    }
    if (c) redisFree(c);
    return ok;
  }

  std::string log_tail() const {
    std::ifstream in{log_path()};
    std::stringstream text;
    text << in.rdbuf();
    auto all = text.str();
    return all.size() > 2000 ? all.substr(all.size() - 2000) : all;
  }

  Config config_;
  std::filesystem::path dir_;
  int port_ = 0;
  std::optional<ChildProcess> process_;
};

}  // namespace prime::test
