// PosixMqueue: two POSIX message queues (mq_open, mq_timedsend,
// mq_timedreceive). Every payload goes through the kernel: mq_send copies all
// `bytes` in, mq_receive copies them out into the receiver's buffer.
//
//   Latency     the parent sends `bytes` on one queue, the child receives them
//               and sends `bytes` back on the other: symmetric.
//   Throughput  the child sends back-to-back on a queue kStreamDepth deep
//               (blocking when it is full, so nothing is lost); the parent
//               receives one message per iteration.
//
// Limits. mq_open refuses messages above fs.mqueue.msgsize_max (8 KiB by
// default) and depths above fs.mqueue.msg_max (10), unless the process has
// CAP_SYS_RESOURCE (root), which lifts both to the kernel's hard limits
// (16 MiB, 65536). Without it, this peer raises the two sysctls while it
// creates its queues, if it may write them, and puts them back. All queues of
// a user together are charged against RLIMIT_MSGQUEUE (800 KiB by default),
// which this process raises as far as it is allowed; a sandbox may forbid
// raising it even to root. Payloads that cannot fit are not registered, and
// the run's context (mqueue_skipped_*) says why.

#include <fcntl.h>
#include <mqueue.h>
#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <cerrno>
#include <cstdint>
#include <ctime>
#include <fstream>
#include <span>
#include <string>
#include <system_error>
#include <utility>

#include "harness.hpp"
#include "payload.hpp"

namespace {

namespace ipc = prime::bench::ipc;
using namespace std::chrono_literals;

constexpr const char* kMsgSizeMax = "/proc/sys/fs/mqueue/msgsize_max";
constexpr const char* kMsgMax = "/proc/sys/fs/mqueue/msg_max";
constexpr long kHardMsgSizeMax = 16L << 20;  // the kernel's HARD_MSGSIZEMAX
constexpr long kHardMsgMax = 65536;          // and HARD_MSGMAX
constexpr int kCapSysResource = 24;
// Blocking calls give up after this long, so a wait can look at the other process.
constexpr auto kSlice = 50ms;

long read_number(const char* path) {
  std::ifstream file{path};
  long value = -1;
  file >> value;
  return value;
}

bool has_cap_sys_resource() {
  std::ifstream status{"/proc/self/status"};
  for (std::string line; std::getline(status, line);)
    if (line.starts_with("CapEff:")) return (std::stoull(line.substr(7), nullptr, 16) >> kCapSysResource) & 1U;
  return false;
}

// A sysctl raised to at least `value` for as long as this lives.
class RaisedSysctl {
 public:
  RaisedSysctl(const char* path, long value) : path_{path}, old_{read_number(path)} {
    if (old_ >= value) return;
    std::ofstream file{path};
    file << value;
    file.close();
    raised_ = file.good();
  }
  RaisedSysctl(const RaisedSysctl&) = delete;
  RaisedSysctl& operator=(const RaisedSysctl&) = delete;
  ~RaisedSysctl() {
    if (raised_) std::ofstream{path_} << old_;
  }

 private:
  const char* path_;
  long old_;
  bool raised_ = false;
};

// What mq_open can be brought to accept in this process.
struct Limits {
  long message;      // the largest message
  long depth;        // the deepest queue
  rlim_t all_bytes;  // RLIMIT_MSGQUEUE, raised as far as allowed
};

const Limits& limits() {
  static const Limits l = [] {
    rlimit r{RLIM_INFINITY, RLIM_INFINITY};
    if (::setrlimit(RLIMIT_MSGQUEUE, &r) != 0 && ::getrlimit(RLIMIT_MSGQUEUE, &r) == 0) {
      r.rlim_cur = r.rlim_max;
      ::setrlimit(RLIMIT_MSGQUEUE, &r);
    }
    ::getrlimit(RLIMIT_MSGQUEUE, &r);
    if (has_cap_sys_resource() || (::access(kMsgSizeMax, W_OK) == 0 && ::access(kMsgMax, W_OK) == 0))
      return Limits{kHardMsgSizeMax, kHardMsgMax, r.rlim_cur};
    return Limits{read_number(kMsgSizeMax), read_number(kMsgMax), r.rlim_cur};
  }();
  return l;
}

// Whether `queues` queues of `depth` messages of `bytes` can exist at once.
// The kernel charges each message its size plus some bookkeeping (a msg_msg
// and a tree node, under kBookkeeping) against RLIMIT_MSGQUEUE.
constexpr long kBookkeeping = 128;

bool fits(long queues, long depth, std::int64_t bytes) {
  const Limits& l = limits();
  if (bytes > l.message || depth > l.depth) return false;
  return l.all_bytes == RLIM_INFINITY ||
         static_cast<rlim_t>(queues * depth * (bytes + kBookkeeping)) <= l.all_bytes;
}

// The depth of a throughput queue: kStreamDepth, or as deep as the limits
// allow. Below kMinStreamDepth it is hardly a stream, and is not measured.
constexpr long kMinStreamDepth = 8;

long stream_depth(std::int64_t bytes) {
  const Limits& l = limits();
  long depth = std::min(static_cast<long>(ipc::kStreamDepth), l.depth);
  if (l.all_bytes != RLIM_INFINITY)
    depth = std::min(depth, static_cast<long>(l.all_bytes / static_cast<rlim_t>(bytes + kBookkeeping)));
  return bytes <= l.message ? depth : 0;
}

std::string unique_name(const char* role) {
  static std::atomic<int> next{0};
  return "/prime-ipc-" + std::to_string(::getpid()) + "-" + std::to_string(next++) + "-" + role;
}

// One open message queue. The one that created it removes its name at the
// latest when it closes; the queue itself lives until both ends are closed.
class MessageQueue {
 public:
  static MessageQueue create(const char* role, std::size_t bytes, long depth) {
    (void)limits();  // raises RLIMIT_MSGQUEUE
    MessageQueue queue{unique_name(role)};
    mq_attr attr{};
    attr.mq_maxmsg = depth;
    attr.mq_msgsize = static_cast<long>(bytes);
    queue.queue_ = ::mq_open(queue.name_.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600, &attr);
    if (queue.queue_ == kClosed && errno == EINVAL) {
      const RaisedSysctl size{kMsgSizeMax, attr.mq_msgsize};
      const RaisedSysctl count{kMsgMax, depth};
      queue.queue_ = ::mq_open(queue.name_.c_str(), O_RDWR | O_CREAT | O_EXCL | O_CLOEXEC, 0600, &attr);
    }
    if (queue.queue_ == kClosed) {
      const int error = errno;
      throw std::system_error{error, std::generic_category(),
                              "mq_open of " + std::to_string(depth) + " messages of " + std::to_string(bytes) +
                                  " bytes (fs.mqueue.msgsize_max " + std::to_string(read_number(kMsgSizeMax)) +
                                  ", msg_max " + std::to_string(read_number(kMsgMax)) +
                                  (error == EMFILE ? ", and RLIMIT_MSGQUEUE too small)" : ")")};
    }
    queue.owner_ = true;
    return queue;
  }

  static MessageQueue open(const std::string& name) {
    MessageQueue queue{name};
    queue.queue_ = ::mq_open(name.c_str(), O_RDWR | O_CLOEXEC);
    if (queue.queue_ == kClosed) throw std::system_error{errno, std::generic_category(), "mq_open " + name};
    return queue;
  }

  MessageQueue(MessageQueue&& other) noexcept
      : name_{std::move(other.name_)},
        queue_{std::exchange(other.queue_, kClosed)},
        owner_{std::exchange(other.owner_, false)} {}
  MessageQueue& operator=(MessageQueue&&) = delete;
  ~MessageQueue() {
    unlink();
    if (queue_ != kClosed) ::mq_close(queue_);
  }

  // Removes the name once the other process has opened the queue: a name
  // outlives a killed process, an open queue does not.
  void unlink() noexcept {
    if (std::exchange(owner_, false)) ::mq_unlink(name_.c_str());
  }

  [[nodiscard]] const std::string& name() const noexcept { return name_; }

  template <ipc::Side S>
  void send(S& side, std::span<const std::byte> message) {
    ipc::Patience<S> patience{side};
    for (;;) {
      const timespec deadline = in(kSlice);
      if (::mq_timedsend(queue_, reinterpret_cast<const char*>(message.data()), message.size(), 0, &deadline) == 0) return;
      if (errno == ETIMEDOUT) patience.idle();
      else if (errno != EINTR) throw std::system_error{errno, std::generic_category(), "mq_timedsend"};
    }
  }

  template <ipc::Side S>
  void receive(S& side, std::span<std::byte> message) {
    ipc::Patience<S> patience{side};
    for (;;) {
      const timespec deadline = in(kSlice);
      const ssize_t n =
          ::mq_timedreceive(queue_, reinterpret_cast<char*>(message.data()), message.size(), nullptr, &deadline);
      if (n == static_cast<ssize_t>(message.size())) return;
      if (n >= 0) throw ipc::PeerError{"mq_timedreceive: a message of " + std::to_string(n) + " bytes"};
      if (errno == ETIMEDOUT) patience.idle();
      else if (errno != EINTR) throw std::system_error{errno, std::generic_category(), "mq_timedreceive"};
    }
  }

  // Receives and drops one message if there is one, without waiting.
  void discard(std::span<std::byte> message) noexcept {
    const timespec now{};
    (void)::mq_timedreceive(queue_, reinterpret_cast<char*>(message.data()), message.size(), nullptr, &now);
  }

 private:
  static constexpr mqd_t kClosed = static_cast<mqd_t>(-1);

  explicit MessageQueue(std::string name) : name_{std::move(name)} {}

  // mq_timed* take an absolute CLOCK_REALTIME time.
  static timespec in(std::chrono::nanoseconds delay) {
    timespec t{};
    ::clock_gettime(CLOCK_REALTIME, &t);
    const auto ns = t.tv_nsec + delay.count();
    t.tv_sec += static_cast<time_t>(ns / 1'000'000'000);
    t.tv_nsec = static_cast<long>(ns % 1'000'000'000);
    return t;
  }

  std::string name_;
  mqd_t queue_ = kClosed;
  bool owner_ = false;
};

// ---- payload sizes: those mq_open can be brought to accept -----------------

// Why `queues` queues of `depth` messages of `bytes` cannot be had.
std::string why_not(long queues, long depth, std::int64_t bytes) {
  const Limits& l = limits();
  if (bytes > l.message)
    return "messages of " + std::to_string(bytes) + " B exceed fs.mqueue.msgsize_max (" + std::to_string(l.message) +
           " B), which this process may not raise";
  return std::to_string(queues) + " queue(s) of " + std::to_string(depth) + " × " + std::to_string(bytes) +
         " B exceed RLIMIT_MSGQUEUE (" + std::to_string(l.all_bytes) + " B), which this process may not raise";
}

void mqueue_latency_payloads(benchmark::internal::Benchmark* b) {
  for (const auto bytes : ipc::kLatencyPayloads) {
    if (fits(2, 1, bytes)) b->Arg(bytes);
    else benchmark::AddCustomContext("mqueue_skipped_latency_" + std::to_string(bytes), why_not(2, 1, bytes));
  }
  b->UseRealTime();
}

void mqueue_throughput_payloads(benchmark::internal::Benchmark* b) {
  for (const auto bytes : ipc::kThroughputPayloads) {
    if (stream_depth(bytes) >= kMinStreamDepth) b->Arg(bytes);
    else
      benchmark::AddCustomContext("mqueue_skipped_throughput_" + std::to_string(bytes), why_not(1, kMinStreamDepth, bytes));
  }
  b->UseRealTime();
}

// ---- the peer ---------------------------------------------------------------

void echo(ipc::Child& self) {
  auto ping = MessageQueue::open(self.arg(0));
  auto pong = MessageQueue::open(self.arg(1));
  ipc::Payload message{self.bytes()};
  self.ready();
  for (;;) {
    ping.receive(self, message.bytes());
    pong.send(self, message.bytes());
  }
}
const ipc::ChildEntry kEcho{"PosixMqueue.echo", echo};

void stream(ipc::Child& self) {
  auto queue = MessageQueue::open(self.arg(0));
  ipc::Payload message{self.bytes()};
  self.ready();
  for (std::uint64_t seq = 1;; ++seq) {
    self.check();
    message.stamp(seq);
    queue.send(self, message.bytes());
  }
}
const ipc::ChildEntry kStream{"PosixMqueue.stream", stream};

void BM_Latency_PosixMqueue(benchmark::State& state) {
  ipc::run(state, [&](std::size_t bytes) {
    // One message in flight each way: a depth of one is all a ping-pong needs.
    auto ping = MessageQueue::create("ping", bytes, 1);
    auto pong = MessageQueue::create("pong", bytes, 1);
    ipc::Link child{"PosixMqueue.echo", bytes, {}, {ping.name(), pong.name()}};
    ipc::Payload out{bytes};
    ipc::Payload in{bytes};
    child.wait_ready();
    ping.unlink();
    pong.unlink();
    child.go();
    ipc::time_round_trips(state, [&](std::uint64_t seq) {
      out.stamp(seq);
      ping.send(child, out.bytes());
      pong.receive(child, in.bytes());
      if (in.seq() != seq) throw ipc::out_of_sequence(seq, in.seq());
    });
    child.stop();
  });
}
BENCHMARK(BM_Latency_PosixMqueue)->Apply(mqueue_latency_payloads);

void BM_Throughput_PosixMqueue(benchmark::State& state) {
  ipc::run(state, [&](std::size_t bytes) {
    const long depth = stream_depth(static_cast<std::int64_t>(bytes));
    auto queue = MessageQueue::create("stream", bytes, depth);
    ipc::Link child{"PosixMqueue.stream", bytes, {}, {queue.name()}};
    ipc::Payload in{bytes};
    child.set_drain([&] { queue.discard(in.bytes()); });
    child.wait_ready();
    queue.unlink();
    child.go();
    ipc::time_stream(state, [&](std::uint64_t seq) {
      queue.receive(child, in.bytes());
      if (in.seq() != seq) throw ipc::out_of_sequence(seq, in.seq());
    });
    child.stop();
    state.counters["depth"] = static_cast<double>(depth);
  });
}
BENCHMARK(BM_Throughput_PosixMqueue)->Apply(mqueue_throughput_payloads);

}  // namespace
