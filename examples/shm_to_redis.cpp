// A bridge between media: the robot's odometry, published in shared memory by
// its driver process, is forwarded into Redis, where a watcher (on another
// machine, in practice) reads it.
//
//   process "odometry"            process "bridge"                          anywhere
//   driver ──loan/publish──> shm "odom" ──> forward ──XADD──> redis stream "odom" ──> watcher
//
// Usage: shm_to_redis [redis-url]   (default: starts a private redis-server on a Unix socket)
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <optional>
#include <stdexcept>
#include <string>
#include <thread>

#include "prime/optimus.hpp"
#include "prime/shm.hpp"

using namespace std::chrono_literals;
extern char** environ;

struct Odometry {
  double x, y, speed;
};

// A redis-server of our own, on a Unix socket in a fresh directory, for as
// long as this object lives.
class PrivateRedis {
 public:
  PrivateRedis() : dir_{std::filesystem::temp_directory_path() / ("prime-redis-" + std::to_string(::getpid()))} {
    std::filesystem::create_directories(dir_);
    const std::string socket = (dir_ / "redis.sock").string();
    std::string args[] = {"redis-server", "--port", "0", "--unixsocket", socket, "--save", "", "--appendonly", "no",
                          "--dir", dir_.string(), "--logfile", (dir_ / "redis.log").string()};
    char* argv[std::size(args) + 1] = {};
    for (std::size_t i = 0; i < std::size(args); ++i) argv[i] = args[i].data();
    if (::posix_spawnp(&pid_, "redis-server", nullptr, nullptr, argv, environ) != 0)
      throw std::runtime_error{"cannot start redis-server (Debian package redis-server)"};
    url_ = "unix://" + socket;
    for (int i = 0; i < 500 && !std::filesystem::exists(socket); ++i) std::this_thread::sleep_for(10ms);
  }
  ~PrivateRedis() {
    ::kill(pid_, SIGTERM);
    ::waitpid(pid_, nullptr, 0);
    std::filesystem::remove_all(dir_);
  }
  PrivateRedis(const PrivateRedis&) = delete;
  PrivateRedis& operator=(const PrivateRedis&) = delete;
  [[nodiscard]] const std::string& url() const { return url_; }

 private:
  std::filesystem::path dir_;
  pid_t pid_ = -1;
  std::string url_;
};

int odometry_driver(const std::string& domain) {
  prime::shm::Core shm{domain, {.participant = "odometry"}};
  auto odom = shm.publisher<Odometry>("odom");
  for (int i = 0; i < 50; ++i) {
    auto sample = odom.loan();
    if (!sample) return 1;
    **sample = Odometry{0.1 * i, 0.0, 0.5};
    std::move(*sample).publish();
    std::this_thread::sleep_for(20ms);
  }
  return 0;
}

int main(int argc, char** argv) {
  const std::string domain = "shm-to-redis-" + std::to_string(::getpid());
  const pid_t driver = ::fork();  // before any thread or segment exists
  if (driver == 0) {
    std::_Exit(odometry_driver(domain));
  }

  std::optional<PrivateRedis> own;
  std::string url = argc > 1 ? argv[1] : (own.emplace(), own->url());
  prime::optimus::Core watcher{prime::optimus::Options{.url = url, .domain = domain}};  // another machine, say
  auto watched = watcher.subscribe<Odometry>("odom").subscribe();

  prime::shm::Core robot{domain, {.participant = "bridge"}};
  prime::optimus::Core uplink{prime::optimus::Options{.url = url, .domain = domain}};
  // history: whatever the driver published before the bridge joined (up to the capacity)
  prime::forward(robot.subscribe<Odometry>("odom", {.history = 64}),
                 [out = uplink.publisher<Odometry>("odom")](const prime::shm::View<Odometry>& o,
                                                            prime::Clock::time_point stamp) {
                   return out.publish(*o, stamp);  // one XADD; a failure is reported on robot.errors()
                 },
                 "odom to redis");

  int seen = 0;
  while (auto o = watched.read_for(2s)) {
    if (++seen % 10 == 0) std::printf("watcher: odom x=%.1f m, speed %.1f m/s (%d seen)\n", o->value.x, o->value.speed, seen);
    if (seen == 50) break;
  }
  int status = 0;
  ::waitpid(driver, &status, 0);
  std::printf("watcher saw %d of 50 odometry samples through Redis\n", seen);
  return seen == 50 && WIFEXITED(status) && WEXITSTATUS(status) == 0 ? 0 : 1;
}
