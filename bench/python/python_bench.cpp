// prime_python_bench: C++ to Python through Shm, beside C++ to C++ (prime_ipc's
// Latency_Shm and Throughput_Shm) in `prime bench`. The reader is a Python
// process (reader.py) using the prime package, reading each sample in place
// through numpy.
//
//   Latency_ShmToPython/<bytes>     one sample at a time on a raw topic: the
//       parent publishes (its sequence in the first 8 bytes), Python reads it
//       and answers with the steady clock's time it read it; a sample is that
//       time minus the publish stamp, one way (p50_ns ...; prime_ipc's
//       Latency_Shm is half a round trip). Flat from 64 B to 1 MiB: nothing
//       is copied on the way.
//   Throughput_ShmToPython/<bytes>  the parent publishes flat out on a `block`
//       topic; msgs/s is the rate Python reads every sample at, losslessly.
//   RoundTrip_ShmServiceInPython/<bytes>  the parent calls a raw service
//       that Python serves (Domain.serve: the request copied into bytes, the
//       Python function run with the GIL, its reply copied into the reply's
//       cell), beside prime_ipc's RoundTrip_ShmService (served in C++, in
//       place both ways). p50_ns ... are half the round trip, as prime_ipc's
//       RoundTrip rows are (the report doubles both).
#include <benchmark/benchmark.h>
#include <fcntl.h>
#include <poll.h>
#include <signal.h>
#include <spawn.h>
#include <sys/wait.h>
#include <unistd.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <stdexcept>
#include <string>
#include <system_error>
#include <vector>

#include "prime/shm.hpp"

extern char** environ;

namespace {

namespace shm = prime::shm;
using namespace std::chrono_literals;
using prime::Clock;

// The Python reader, started with the package on its path; stopped with its
// object (SIGKILL: it holds nothing the parent needs).
class PythonReader {
 public:
  PythonReader(const std::string& mode, const std::string& domain) {
    int out[2];
    if (::pipe2(out, O_CLOEXEC) != 0) throw std::system_error{errno, std::generic_category(), "pipe"};
    posix_spawn_file_actions_t actions;
    posix_spawn_file_actions_init(&actions);
    posix_spawn_file_actions_adddup2(&actions, out[1], STDOUT_FILENO);
    posix_spawn_file_actions_addclose(&actions, out[0]);
    std::vector<std::string> env{"PYTHONPATH=" PRIME_PYTHON_PATH};
    for (char** e = environ; *e; ++e)
      if (std::strncmp(*e, "PYTHONPATH=", 11) != 0) env.emplace_back(*e);
    std::vector<char*> envp;
    for (auto& e : env) envp.push_back(e.data());
    envp.push_back(nullptr);
    std::string python = PRIME_PYTHON_EXECUTABLE, script = PRIME_PYTHON_READER;
    std::string m = mode, d = domain;
    char* argv[] = {python.data(), script.data(), m.data(), d.data(), nullptr};
    const int spawned = posix_spawn(&pid_, python.c_str(), &actions, nullptr, argv, envp.data());
    posix_spawn_file_actions_destroy(&actions);
    ::close(out[1]);
    if (spawned != 0) {
      ::close(out[0]);
      throw std::system_error{spawned, std::generic_category(), "starting " + python};
    }
    output_ = out[0];
    if (!said_ready()) {
      stop();
      throw std::runtime_error{"the Python reader did not start within 30 s (is the prime package built?)"};
    }
  }
  ~PythonReader() { stop(); }
  PythonReader(const PythonReader&) = delete;
  PythonReader& operator=(const PythonReader&) = delete;

 private:
  // Whether the reader writes "ready\n" within 30 s.
  bool said_ready() const {
    std::string said;
    const auto deadline = Clock::now() + 30s;
    while (said.size() < 6 && Clock::now() < deadline) {
      pollfd p{.fd = output_, .events = POLLIN, .revents = 0};
      if (::poll(&p, 1, 100) <= 0) continue;
      char c;
      if (::read(output_, &c, 1) != 1) return false;
      said += c;
    }
    return said == "ready\n";
  }
  void stop() {
    ::kill(pid_, SIGKILL);
    ::waitpid(pid_, nullptr, 0);
    ::close(output_);
  }

  pid_t pid_ = 0;
  int output_ = -1;
};

std::string new_domain() {
  static int n = 0;
  return "prime-pybench-" + std::to_string(::getpid()) + "-" + std::to_string(n++);
}

// The reader's answers: a sequence and a time (ns of the steady clock).
struct Answer {
  std::uint64_t seq;
  std::uint64_t read_ns;
};

// Waits (busy, as the C++ to C++ benchmarks do) for the answer that carries `seq`.
Answer wait_for(prime::Reader<shm::View<shm::Bytes>>& pong, std::uint64_t seq) {
  const auto deadline = Clock::now() + 10s;
  while (Clock::now() < deadline) {
    if (auto s = pong.try_read()) {
      if (s->value.bytes().size() != sizeof(Answer)) throw std::runtime_error{"the Python reader answered a wrong size"};
      Answer a;
      std::memcpy(&a, s->value.bytes().data(), sizeof a);
      if (a.seq >= seq) return a;
    }
  }
  throw std::runtime_error{"the Python reader did not answer within 10 s"};
}

void publish(shm::Publisher<shm::Bytes>& out, std::size_t bytes, std::uint64_t seq, Clock::time_point stamp) {
  auto loan = out.loan(bytes);
  if (!loan) throw prime::Failure{loan.error()};
  std::memcpy(loan->bytes().data(), &seq, sizeof seq);
  std::move(*loan).publish(stamp);
}

// The p50, p90 and p99 of `samples` (ns) as the benchmark's counters.
void percentiles(benchmark::State& state, std::vector<std::uint32_t>& samples) {
  if (samples.empty()) return;
  auto at = [&](double q) {
    const auto k = std::min(samples.size() - 1, static_cast<std::size_t>(q * static_cast<double>(samples.size())));
    std::nth_element(samples.begin(), samples.begin() + static_cast<std::ptrdiff_t>(k), samples.end());
    return static_cast<double>(samples[k]);
  };
  state.counters["p50_ns"] = at(0.5);
  state.counters["p90_ns"] = at(0.9);
  state.counters["p99_ns"] = at(0.99);
}

void BM_Latency_ShmToPython(benchmark::State& state) try {
  const auto bytes = static_cast<std::size_t>(state.range(0));
  const auto domain = new_domain();
  shm::Core core{domain};
  auto ping = core.publisher<shm::Bytes>("ping", {.capacity = 4, .max_message_size = bytes});
  auto pong = core.subscribe<shm::Bytes>("pong", {}, {.capacity = 4, .max_message_size = sizeof(Answer)}).subscribe();
  PythonReader reader{"latency", domain};
  std::vector<std::uint32_t> samples;
  std::uint64_t seq = 0;
  for (int i = 0; i < 100; ++i) {  // warm: the interpreter's first passes, page faults
    publish(ping, bytes, ++seq, Clock::now());
    (void)wait_for(pong, seq);
  }
  for (auto _ : state) {
    const auto sent = Clock::now();
    publish(ping, bytes, ++seq, sent);
    const auto answer = wait_for(pong, seq);
    const auto one_way = static_cast<std::int64_t>(answer.read_ns) -
                         std::chrono::duration_cast<std::chrono::nanoseconds>(sent.time_since_epoch()).count();
    if (one_way < 0) throw std::runtime_error{"Python read a sample before it was published: the clocks differ"};
    samples.push_back(static_cast<std::uint32_t>(std::min<std::int64_t>(one_way, UINT32_MAX)));
  }
  percentiles(state, samples);
} catch (const std::exception& e) {
  state.SkipWithError(e.what());
}
BENCHMARK(BM_Latency_ShmToPython)->Arg(64)->Arg(1 << 20)->UseRealTime();

void BM_Throughput_ShmToPython(benchmark::State& state) try {
  const auto bytes = static_cast<std::size_t>(state.range(0));
  const auto domain = new_domain();
  shm::Core core{domain};
  auto stream = core.publisher<shm::Bytes>(
      "stream", {.capacity = 256, .max_message_size = bytes, .overflow = prime::Overflow::block, .block_timeout = 10s});
  auto pong = core.subscribe<shm::Bytes>("pong", {}, {.capacity = 4, .max_message_size = sizeof(Answer)}).subscribe();
  PythonReader reader{"stream", domain};
  constexpr std::uint64_t kRound = 4096;  // a multiple of the reader's 256
  std::uint64_t seq = 0;
  auto round = [&] {
    for (std::uint64_t i = 0; i < kRound; ++i) publish(stream, bytes, ++seq, Clock::now());
    if (wait_for(pong, seq).read_ns != 0) throw std::runtime_error{"the Python reader missed a sample"};
  };
  round();  // warm
  const auto start = Clock::now();
  for (auto _ : state) round();
  const std::chrono::duration<double> elapsed = Clock::now() - start;
  state.counters["msgs/s"] = static_cast<double>(state.iterations() * kRound) / elapsed.count();
} catch (const std::exception& e) {
  state.SkipWithError(e.what());
}
BENCHMARK(BM_Throughput_ShmToPython)->Arg(64)->Arg(1 << 20)->UseRealTime();

void BM_RoundTrip_ShmServiceInPython(benchmark::State& state) try {
  const auto bytes = static_cast<std::size_t>(state.range(0));
  const auto domain = new_domain();
  shm::Core core{domain};
  PythonReader server{"serve", domain};
  auto echo = core.chain<shm::Bytes, shm::Bytes>("echo", {.timeout = 10s, .wait_for_service = 10s});
  std::vector<std::uint32_t> samples;
  std::uint64_t seq = 0;
  auto call = [&] {
    ++seq;
    std::uint64_t got = 0;
    std::size_t size = 0;
    const auto done = echo.call_in_place(
        [&](std::span<std::byte> request) {
          std::memcpy(request.data(), &seq, sizeof seq);
          return bytes;
        },
        [&](std::span<const std::byte> reply) {
          size = reply.size();
          if (size >= sizeof got) std::memcpy(&got, reply.data(), sizeof got);
        });
    if (!done) throw prime::Failure{done.error()};
    if (got != seq || size != bytes) throw std::runtime_error{"the Python service answered another request"};
  };
  for (int i = 0; i < 100; ++i) call();  // warm: the interpreter's first passes, page faults
  for (auto _ : state) {
    const auto sent = Clock::now();
    call();
    const auto round_trip = std::chrono::duration_cast<std::chrono::nanoseconds>(Clock::now() - sent).count();
    samples.push_back(static_cast<std::uint32_t>(std::min<std::int64_t>(round_trip / 2, UINT32_MAX)));
  }
  percentiles(state, samples);
} catch (const std::exception& e) {
  state.SkipWithError(e.what());
}
BENCHMARK(BM_RoundTrip_ShmServiceInPython)->Arg(64)->Arg(64 << 10)->Arg(1 << 20)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
