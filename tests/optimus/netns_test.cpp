// Across hosts: a service in a network namespace of its own, reaching the
// server over a veth pair with private test addresses, as a service on
// another machine would. Needs root (CAP_SYS_ADMIN, CAP_NET_ADMIN) and `ip`;
// where the machine does not allow it, the test skips and says why.
#include <gtest/gtest.h>

#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <string>
#include <vector>

#include "optimus/support/child_process.hpp"
#include "optimus/support/optimus_fixture.hpp"

namespace prime::test {
namespace {

// Runs a command to completion; its exit status (-1 when it could not run).
int run(std::vector<std::string> argv) {
  ChildProcess child{std::move(argv), "/dev/null"};
  while (child.read_line(10s)) {
  }
  const int status = child.stop(10s);
  return WIFEXITED(status) ? WEXITSTATUS(status) : -1;
}

// A namespace and a veth pair between it and this one, 10.231.<n>.1/30 here
// and .2/30 there; removed when the object goes.
class TestHost {
 public:
  TestHost() : n_{static_cast<int>(::getpid() % 250) + 1}, ns_{"prime-optimus-" + std::to_string(::getpid())} {
    outer_ = "po" + std::to_string(::getpid() % 100000) + "a";
    inner_ = "po" + std::to_string(::getpid() % 100000) + "b";
    if (::geteuid() != 0) {
      why_not_ = "not root: making a network namespace needs CAP_SYS_ADMIN and CAP_NET_ADMIN";
      return;
    }
    if (run({"ip", "netns", "add", ns_}) != 0) {
      why_not_ = "'ip netns add' failed (no iproute2, or the sandbox forbids network namespaces)";
      return;
    }
    made_ns_ = true;
    const std::vector<std::vector<std::string>> steps{
        {"ip", "link", "add", outer_, "type", "veth", "peer", "name", inner_},
        {"ip", "link", "set", inner_, "netns", ns_},
        {"ip", "addr", "add", host_address() + "/30", "dev", outer_},
        {"ip", "link", "set", outer_, "up"},
        {"ip", "netns", "exec", ns_, "ip", "addr", "add", guest_address() + "/30", "dev", inner_},
        {"ip", "netns", "exec", ns_, "ip", "link", "set", inner_, "up"},
        {"ip", "netns", "exec", ns_, "ip", "link", "set", "lo", "up"},
    };
    for (const auto& step : steps) {
      if (run(step) != 0) {
        why_not_ = "setting up the veth pair failed at: " + step[1] + " " + step[2] + " " + step[3];
        return;
      }
    }
  }
  TestHost(const TestHost&) = delete;
  TestHost& operator=(const TestHost&) = delete;
  ~TestHost() {
    if (!made_ns_) return;
    run({"ip", "link", "del", outer_});  // takes its peer along, if still here
    run({"ip", "netns", "del", ns_});
  }

  [[nodiscard]] const std::string& why_not() const { return why_not_; }
  [[nodiscard]] std::string host_address() const { return "10.231." + std::to_string(n_) + ".1"; }
  [[nodiscard]] std::string guest_address() const { return "10.231." + std::to_string(n_) + ".2"; }
  [[nodiscard]] std::vector<std::string> exec_in() const { return {"ip", "netns", "exec", ns_}; }

 private:
  int n_;
  std::string ns_, outer_, inner_;
  std::string why_not_;
  bool made_ns_ = false;
};

TEST(OptimusAcrossHosts, AServiceInItsOwnNetworkNamespaceIsCalledOverVeth) {
  TestHost guest;
  if (!guest.why_not().empty()) GTEST_SKIP() << guest.why_not();
  RedisServer redis{{.bind = {"127.0.0.1", guest.host_address()}}};
  const std::string domain = unique_domain("netns");
  auto argv = guest.exec_in();
  argv.insert(argv.end(), {PRIME_OPTIMUS_HELPER, "tcp://" + guest.host_address() + ":" + std::to_string(redis.port()),
                           domain, "serve"});
  ChildProcess service{argv};
  ASSERT_TRUE(service.wait_for_line("ready", 20s)) << "the service in the namespace did not reach the server";

  optimus::Core core{optimus::Options{.url = redis.url(), .domain = domain}};
  auto pipeline = core.service<int, int>("add_one") | core.service<int, int>("times_ten");
  EXPECT_EQ(pipeline(4), 50);
  EXPECT_EQ((core.service<int, int>("whoami")(0)), service.pid());
  // The server sees the service's connections come from the other "host".
  RawRedis raw{redis.url()};
  const auto clients = raw.text({"CLIENT", "LIST"});
  EXPECT_NE(clients.find("addr=" + guest.guest_address() + ":"), std::string::npos) << clients;
}

}  // namespace
}  // namespace prime::test
