#include "iceoryx_runtime.hpp"

#include <fcntl.h>
#include <signal.h>
#include <sys/file.h>
#include <unistd.h>

#include <atomic>
#include <cerrno>
#include <charconv>
#include <filesystem>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>
#include <thread>

#include "harness.hpp"
#include "iceoryx_hoofs/log/logmanager.hpp"
#include "iceoryx_posh/runtime/posh_runtime.hpp"
#include "memory_file.hpp"
#include "unique_fd.hpp"

namespace prime::bench::ipc::iceoryx {

namespace {

namespace fs = std::filesystem;
using namespace std::chrono_literals;

// ---- RouDi -----------------------------------------------------------------

// The lock every RouDi holds while it runs (iceoryx 2.0: ROUDI_LOCK_NAME in
// IOX_LOCK_FILE_PATH_PREFIX).
constexpr const char* kRoudiLock = "/tmp/iox-unique-roudi.lock";
constexpr const char* kRoudiReady = "RouDi is ready for clients";

// Mempools: every payload size the benchmarks loan, with room for a stream's
// full queue (kStreamDepth) plus the chunks a publisher may hold (8) and
// slack. `size` is the user payload; RouDi adds the chunk header (40 B). A
// request or response also carries an RPC header (24 or 32 B) in the same
// chunk, so its N bytes do not fit the pool for N: the pools of N + 1 KiB
// hold the round trips' chunks (two at a time: one request, one response),
// which would otherwise take the next larger pool's (a 1 MiB request a 4 MiB
// chunk) or, with none larger, abort the process: iceoryx 2.0 treats a chunk
// too large for every pool as fatal (MEPOO__MEMPOOL_GETCHUNK_CHUNK_IS_TOO_LARGE)
// instead of failing the loan. Cyclone DDS's chunks carry its own header
// (56 B; 108 B with the payload's offset and alignment) before the N bytes,
// so its round trips take the pools of N + 1 KiB too (64 B: 4 KiB's), up
// to four chunks a direction (the one loaned, one queued, one in the
// reader's history, and the last one sent, which an iceoryx publisher
// keeps): 16 of each, and a pool for 4 MiB + 1 KiB. RouDi writes zeros over
// all of it: about 530 MiB of /dev/shm while it runs.
constexpr const char* kRoudiConfig = R"(# Written by prime_ipc for the RouDi it starts.
[general]
version = 1

[[segment]]

[[segment.mempool]]
size = 128
count = 1024

[[segment.mempool]]
size = 4096
count = 64

[[segment.mempool]]
size = 5120
count = 16

[[segment.mempool]]
size = 65536
count = 64

[[segment.mempool]]
size = 66560
count = 16

[[segment.mempool]]
size = 1048576
count = 320

[[segment.mempool]]
size = 1049600
count = 16

[[segment.mempool]]
size = 4194304
count = 16

[[segment.mempool]]
size = 4195328
count = 16
)";


// Throws if a RouDi is running that this process did not start: there can be
// only one per machine, and a foreign one has its own mempools (and clients).
void refuse_foreign_roudi() {
  const UniqueFd lock{::open(kRoudiLock, O_RDONLY | O_CLOEXEC)};
  if (!lock) return;  // no RouDi has run since boot
  if (::flock(lock.get(), LOCK_EX | LOCK_NB) != 0) {
    if (errno != EWOULDBLOCK) throw std::system_error{errno, std::generic_category(), std::string{"flock "} + kRoudiLock};
    throw PeerError{std::string{"an iox-roudi that prime_ipc did not start is running (it holds "} + kRoudiLock +
                         "); stop it first: prime_ipc starts its own, with mempools for payloads up to 4 MiB"};
  }
  ::flock(lock.get(), LOCK_UN);
}

// Removes what runtimes of an earlier, killed prime_ipc left in /tmp: iceoryx
// 2.0 leaves a socket and a lock file per runtime, and ours are named after
// the parent's pid (prime-ipc-<pid>, prime-ipc-child-<pid>-<n>).
void remove_stale_runtime_files() {
  std::error_code error;
  for (const auto& entry : fs::directory_iterator{iox::platform::IOX_UDS_SOCKET_PATH_PREFIX, error}) {
    const std::string file = entry.path().filename().string();
    std::string_view name = file;
    if (!name.starts_with("prime-ipc-")) continue;
    name.remove_prefix(std::string_view{"prime-ipc-"}.size());
    if (name.starts_with("child-")) name.remove_prefix(std::string_view{"child-"}.size());
    pid_t pid = 0;
    const auto [end, parsed] = std::from_chars(name.data(), name.data() + name.size(), pid);
    if (parsed != std::errc{} || pid == ::getpid()) continue;
    if (::kill(pid, 0) != 0 && errno == ESRCH) fs::remove(entry.path(), error);
  }
}

// The RouDi of this benchmark: started with a generated config, its output
// kept in memory; stopped with SIGTERM (SIGKILL after five seconds).
class Roudi {
 public:
  Roudi() {
    refuse_foreign_roudi();
    remove_stale_runtime_files();
    config_.write(kRoudiConfig);
    ChildProcess::Options options;
    options.inherit_fds = {config_.fd()};
    options.cpus = startup_cpus();
    options.output_fd = output_.fd();
    process_.emplace(PRIME_IPC_IOX_ROUDI,
                     std::vector<std::string>{PRIME_IPC_IOX_ROUDI, "-c", config_.path(), "-l", "info"}, options);
    const auto deadline = std::chrono::steady_clock::now() + kPatience;
    while (output_.read().find(kRoudiReady) == std::string::npos) {
      if (const auto status = process_->poll())
        fail("iox-roudi " + ChildProcess::describe(*status) + " before it was ready");
      if (std::chrono::steady_clock::now() > deadline) fail("iox-roudi was not ready within 10 s");
      std::this_thread::sleep_for(10ms);
    }
  }
  Roudi(const Roudi&) = delete;
  Roudi& operator=(const Roudi&) = delete;
  ~Roudi() {
    process_->signal(SIGTERM);
    process_->wait_for(5s);
  }

 private:
  [[noreturn]] void fail(const std::string& what) {
    std::string output = output_.read();
    if (output.size() > 2000) output = "..." + output.substr(output.size() - 2000);
    throw PeerError{what + "; its output:\n" + output};
  }

  MemoryFile config_{"prime-ipc-roudi.toml"};
  MemoryFile output_{"prime-ipc-roudi.log"};
  std::optional<ChildProcess> process_;
};

void quiet_iceoryx() {
  iox::log::LogManager::GetLogManager().SetDefaultLogLevel(iox::log::LogLevel::kWarn,
                                                           iox::log::LogLevelOutput::kHideLogLevel);
}

}  // namespace

void start_iceoryx() {
  static Roudi roudi;
  static const bool runtime = [] {
    quiet_iceoryx();
    const std::string name = "prime-ipc-" + std::to_string(::getpid());
    iox::runtime::PoshRuntime::initRuntime(iox::RuntimeName_t{iox::cxx::TruncateToCapacity, name});
    return true;
  }();
  (void)runtime;
}

std::string child_runtime_name(const std::string& topic) { return "prime-ipc-child-" + topic; }

void start_child_runtime(const std::string& topic) {
  quiet_iceoryx();
  iox::runtime::PoshRuntime::initRuntime(iox::RuntimeName_t{iox::cxx::TruncateToCapacity, child_runtime_name(topic)});
}

std::string new_topic() {
  static std::atomic<int> next{0};
  return std::to_string(::getpid()) + "-" + std::to_string(next++);
}

iox::capro::ServiceDescription service(const std::string& topic, const char* event) {
  return {"PrimeIpc", iox::capro::IdString_t{iox::cxx::TruncateToCapacity, topic},
          iox::capro::IdString_t{iox::cxx::TruncateToCapacity, event}};
}

}  // namespace prime::bench::ipc::iceoryx
