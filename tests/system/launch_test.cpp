// `prime launch` against real processes: a placement started in order of
// readiness with its output prefixed, shown by `prime ls`, a killed process
// restarted by its policy, Ctrl-C stopping every process, and a wrong
// system refused before anything starts.
#include <gtest/gtest.h>
#include <signal.h>

#include <filesystem>
#include <fstream>

#include "pipeline.hpp"
#include "shm/domain.hpp"
#include "shm/peer_process.hpp"
#include "tool_runs.hpp"

namespace {

using namespace std::chrono_literals;
using prime::test::PeerProcess;

class Launch : public ::testing::Test {
 protected:
  void TearDown() override { std::filesystem::remove(path_); }
  void write(const std::string& placements) {
    std::ofstream{path_} << "system: " << domain_ << R"(
components:
  counter: {type: test.counter, params: {limit: 1000000}}
  doubler: {type: test.doubler}
  checker: {type: test.checker}
placements:
)" << placements;
  }
  PeerProcess launch(std::vector<std::string> more = {}) {
    std::vector<std::string> argv{PRIME_TOOL_PATH, "launch", path_, "--executable", SYSTEM_PEER_PATH, "--grace", "5"};
    argv.insert(argv.end(), more.begin(), more.end());
    return PeerProcess::command(argv, true);
  }

  const std::string domain_ = prime::test::unique_domain("launch");
  const std::string path_ = ::testing::TempDir() + "/" + domain_ + ".yaml";
};

TEST_F(Launch, StartsEachProcessAfterWhatItCallsIsServedAndStopsThemAllOnCtrlC) {
  write("  split:\n    checks: [checker]\n    counts: [counter]\n    doubles: {components: [doubler], restart: on_failure}\n");
  auto launcher = launch({"--placement", "split"});
  // checker calls doubler's service: its process starts before checker's.
  ASSERT_TRUE(launcher.line_starting("launch  | placement 'split' of " + path_ + ": starting counts, doubles, checks", 20s));
  for (const std::string name : {"counts", "doubles", "checks"}) {
    ASSERT_TRUE(launcher.line_starting(std::string{name} + std::string(8 - std::string{name}.size(), ' ') + "| [prime] process '" +
                                       name + "' ready", 20s)) << name;
    ASSERT_TRUE(launcher.line_starting("launch  | '" + std::string{name} + "' is ready (pid ", 20s)) << name;
  }
  ASSERT_TRUE(launcher.says("launch  | every process is ready; Ctrl-C stops them", 20s));

  // prime ls shows each process with the components it hosts.
  const auto ls = prime::test::prime(domain_, {"ls"});
  EXPECT_EQ(ls.code, 0) << ls.out;
  for (const std::string shown : {"counts (counter)", "doubles (doubler)", "checks (checker)"})
    EXPECT_NE(ls.out.find(shown), std::string::npos) << ls.out;

  // A process killed with kill -9 is restarted by its policy (on_failure).
  const auto doubler = ls.out.find("doubles (doubler)");
  ASSERT_NE(doubler, std::string::npos);
  const auto pid_line = ls.out.substr(doubler, ls.out.find('\n', doubler) - doubler);
  pid_t pid = 0;
  for (std::size_t at = pid_line.find_first_of("0123456789", 17); at < pid_line.size() && std::isdigit(pid_line[at]); ++at)
    pid = pid * 10 + (pid_line[at] - '0');
  ASSERT_GT(pid, 0) << pid_line;
  ::kill(pid, SIGKILL);
  EXPECT_TRUE(launcher.line_starting("launch  | 'doubles' was killed by signal 9 (Killed); restarting it in 500 ms (on_failure)", 20s));
  EXPECT_TRUE(launcher.line_starting("launch  | 'doubles' restarted (pid ", 20s));
  EXPECT_TRUE(launcher.line_starting("doubles | [prime] process 'doubles' ready", 20s));

  ::kill(launcher.pid(), SIGINT);
  EXPECT_TRUE(launcher.says("launch  | stopped", 20s));
  EXPECT_EQ(launcher.exit_code(20s), 0);
  const auto after = prime::test::prime(domain_, {"ls"});  // nobody is left in the domain
  for (const std::string shown : {"counts (counter)", "doubles (doubler)", "checks (checker)"})
    EXPECT_EQ(after.out.find(shown), std::string::npos) << after.out;
}

TEST_F(Launch, AProcessThatFailsWithNoRestartMakesTheLaunchFail) {
  write("  p:\n    doubler: [doubler]\n    rest: [counter, checker]\n");
  auto launcher = launch();  // the first placement
  ASSERT_TRUE(launcher.says("launch  | every process is ready; Ctrl-C stops them", 20s));
  const auto ls = prime::test::prime(domain_, {"ls"});
  ASSERT_NE(ls.out.find("rest (counter, checker)"), std::string::npos) << ls.out;
  const auto at = ls.out.find("\ndoubler ");  // a process named after its one component is listed by its name
  ASSERT_NE(at, std::string::npos) << ls.out;
  const pid_t pid = std::stoi(ls.out.substr(ls.out.find_first_of("0123456789", at)));
  ::kill(pid, SIGKILL);
  EXPECT_TRUE(launcher.line_starting("launch  | 'doubler' was killed by signal 9 (Killed); its restart policy is never", 20s));
  ::kill(launcher.pid(), SIGTERM);  // the others stop cleanly; the launch reports the failure
  EXPECT_TRUE(launcher.says("launch  | stopped, after a failure", 20s));
  EXPECT_EQ(launcher.exit_code(20s), 1);
}

TEST_F(Launch, LoadsComponentsFromTheLibrariesTheSystemFileLists) {
  std::ofstream{path_} << "system: " << domain_ << "\nlibraries: [\"" << COMPONENTS_LIBRARY << R"("]
components:
  counter: {type: test.counter, params: {limit: 1000000}}
  echo: {type: test.library_echo}
placements:
  p: {counter: [counter], echoing: [echo]}
)";
  prime::shm::Core shm{domain_, {.participant = "test"}};
  auto echoed = shm.subscribe<pipeline::Count>("echoed", {}, {.capacity = 256, .overflow = prime::Overflow::block}).subscribe();
  auto launcher = launch();
  ASSERT_TRUE(launcher.says("launch  | every process is ready; Ctrl-C stops them", 20s));
  // The library's component, in its own process, echoes the counter's counts.
  auto first = echoed.read_for(10s);
  ASSERT_TRUE(first) << first.error().describe();
  EXPECT_GT(first->value->n, 1000);
  auto next = echoed.read_for(10s);
  ASSERT_TRUE(next) << next.error().describe();
  EXPECT_EQ(next->value->n, first->value->n + 1);
  ::kill(launcher.pid(), SIGINT);
  EXPECT_EQ(launcher.exit_code(20s), 0);
}

// One system launched twice in one domain, each under a namespace of its
// own: two counters, two doublers, two checkers, none in the other's way.
TEST_F(Launch, OneSystemRunsTwiceSideBySideUnderTwoNamespaces) {
  write("  split:\n    checks: [checker]\n    counts: [counter]\n    doubles: [doubler]\n");
  prime::shm::Core shm{domain_, {.participant = "test"}};
  auto left = shm.subscribe<pipeline::Seen>("left/checked", {}, {.capacity = 1024}).subscribe();
  auto right = shm.subscribe<pipeline::Seen>("right/checked", {}, {.capacity = 1024}).subscribe();
  auto first = launch({"--namespace", "left"});
  ASSERT_TRUE(first.says("launch  | every process is ready; Ctrl-C stops them", 20s));
  auto second = launch({"--namespace", "right"});
  ASSERT_TRUE(second.says("launch  | every process is ready; Ctrl-C stops them", 20s));
  for (auto* checked : {&left, &right}) {
    std::int64_t last = 0;
    for (int i = 0; i < 20; ++i) {  // each system's own counts, in order, each answered
      auto got = checked->read_for(10s);
      ASSERT_TRUE(got) << got.error().describe();
      EXPECT_EQ(got->value->tripled, 3 * got->value->doubled);
      EXPECT_TRUE(last == 0 || got->value->doubled == last + 2) << got->value->doubled << " after " << last;
      last = got->value->doubled;
    }
  }
  ::kill(first.pid(), SIGINT);
  ::kill(second.pid(), SIGINT);
  EXPECT_EQ(first.exit_code(20s), 0);
  EXPECT_EQ(second.exit_code(20s), 0);
}

// Whether process `pid` is gone (or a zombie nobody reaped yet: it runs nothing).
bool gone(pid_t pid) {
  std::ifstream stat{"/proc/" + std::to_string(pid) + "/stat"};
  std::string line;
  if (!std::getline(stat, line)) return true;
  const auto state = line.find(") ");
  return state != std::string::npos && line.size() > state + 2 && line[state + 2] == 'Z';
}

// A launcher killed with SIGKILL (it can do nothing): its processes are
// told by the kernel (SIGTERM as their parent dies) and stop themselves,
// not left running unsupervised.
TEST_F(Launch, ProcessesStopWhenTheirLauncherIsKilled) {
  write("  split:\n    checks: [checker]\n    counts: [counter]\n    doubles: [doubler]\n");
  auto launcher = launch();
  std::vector<pid_t> pids;
  for (int i = 0; i < 3; ++i) {
    const auto ready = launcher.next_line_where(
        [](const std::string& line) { return line.starts_with("launch  | '") && line.find("' is ready (pid ") != std::string::npos; }, 20s);
    ASSERT_TRUE(ready);
    const auto at = ready->find("(pid ");
    ASSERT_NE(at, std::string::npos) << *ready;
    pids.push_back(std::stoi(ready->substr(at + 5)));
  }
  ASSERT_TRUE(launcher.says("launch  | every process is ready; Ctrl-C stops them", 20s));
  launcher.kill9();
  const auto give_up = std::chrono::steady_clock::now() + 20s;
  for (const auto pid : pids) {
    while (!gone(pid) && std::chrono::steady_clock::now() < give_up) ::usleep(20'000);  // polls the kernel's process table
    EXPECT_TRUE(gone(pid)) << "process " << pid << " outlived its launcher";
  }
}

TEST_F(Launch, ALibraryThatCannotBeLoadedIsRefusedByLine) {
  std::ofstream{path_} << "system: " << domain_ << "\nlibraries:\n  - ./no_such_library.so\ncomponents:\n  c: {type: test.counter}\n"
                       << "placements:\n  p: {x: [c]}\n";
  auto launcher = launch();
  const auto out = launcher.all_output(30s);
  EXPECT_EQ(launcher.exit_code(20s), 2) << out;
  EXPECT_NE(out.find(path_ + ":3: the library of components './no_such_library.so' cannot be loaded"), std::string::npos) << out;
}

TEST_F(Launch, AWrongSystemIsRefusedBeforeAnythingStarts) {
  write("  p:\n    one: [counter, doubler]\n");  // checker placed nowhere
  auto launcher = launch();
  const auto out = launcher.all_output(30s);
  EXPECT_EQ(launcher.exit_code(20s), 2) << out;
  EXPECT_NE(out.find(path_ + ":7: placement 'p' places component 'checker' in no process"), std::string::npos) << out;
  EXPECT_NE(out.find("nothing was started"), std::string::npos) << out;
  EXPECT_EQ(out.find("[prime] process"), std::string::npos) << out;
}

TEST_F(Launch, AProcessThatFailsToStartStopsTheLaunch) {
  write("  p:\n    one: [counter, doubler, checker]\n");
  auto launcher = launch({"--param", "counter.limit=many"});  // a string for an integer
  const auto out = launcher.all_output(30s);
  EXPECT_EQ(launcher.exit_code(20s), 2) << out;
  EXPECT_NE(out.find("parameter 'limit' is an integer, given a string"), std::string::npos) << out;
}

}  // namespace
