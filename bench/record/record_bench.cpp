// prime record and prime play, measured as a user runs them: the real tool
// in a process of its own, beside a publisher flat out (or paced) in this
// one, into a file on tmpfs (/dev/shm, where it has room).
//
//   BM_RecordFlat/<bytes>          a publisher flat out, the recorder beside it:
//                                  recorded_per_s, recorded_bytes_per_s, lost,
//                                  published_per_s
//   BM_PublisherAlone/<bytes>      the same publisher with no recorder: published_per_s
//   BM_PublisherBesideReader/<bytes>
//                                  the same publisher beside a plain subscriber reading
//                                  busily on the recorder's CPUs (in this process):
//                                  published_per_s, read_per_s; what any reader of
//                                  every sample costs it, against what the recorder does
//   BM_RecordPaced/<bytes>/<hz>/<capacity>
//                                  a publisher at <hz> on a ring <capacity> deep:
//                                  recorded, lost (none is the bar), missing (must be 0)
//   BM_PublishPacedAlone/64/100000/64
//                                  the paced publisher with no recorder: publish_ns (mean)
//                                  and publish_p50_ns (BM_RecordPaced's beside them: what
//                                  the recorder costs it)
//   BM_WriteFloor                  write() of 1 MiB blocks into the same folder on the
//                                  recorder's CPUs: written_bytes_per_s, its floor
//   BM_PlayTiming                  prime play of 2 s at 1 kHz, read by a busy
//                                  reader: timing_error_<p50|p99|max>_ns, each
//                                  sample's arrival against its recorded offset
//
// Seconds per measurement: PRIME_RECORD_SECONDS (2 by default). The tool:
// PRIME_TOOL (prime bench sets it to itself), else the build tree's.
#include <benchmark/benchmark.h>
#include <fcntl.h>
#include <signal.h>
#include <sys/statvfs.h>
#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdlib>
#include <cstring>
#include <filesystem>
#include <string>
#include <thread>
#include <vector>

#include "../ipc/child_process.hpp"
#include "prime/record/mcap_reader.hpp"
#include "prime/record/mcap_writer.hpp"
#include "prime/record/prime_metadata.hpp"
#include "prime/shm.hpp"

namespace {

using namespace std::chrono_literals;
using prime::Clock;
namespace rec = prime::record;
namespace shm = prime::shm;

template <std::size_t N>
struct Blob {
  std::uint64_t seq;
  std::byte rest[N - sizeof(std::uint64_t)];
};

double seconds_per_run() {
  const char* s = std::getenv("PRIME_RECORD_SECONDS");
  const double v = s ? std::atof(s) : 2.0;
  return v > 0 ? v : 2.0;
}

std::string tool() {
  if (const char* t = std::getenv("PRIME_TOOL"); t && *t) return t;
  return PRIME_TOOL_BUILT;
}

std::string new_name(const std::string& what) {
  static std::atomic<int> next{0};
  return "prime-bench-" + what + "-" + std::to_string(::getpid()) + "-" + std::to_string(next++);
}

// Where the recordings go: tmpfs (/dev/shm) where it has room for a few
// seconds at 1 GB/s, else the temporary folder (a CI container's /dev/shm
// may hold 64 MiB).
std::string folder() {
  struct statvfs fs{};
  if (::statvfs("/dev/shm", &fs) == 0 && static_cast<double>(fs.f_bavail) * static_cast<double>(fs.f_frsize) >= 4.0 * (1u << 30))
    return "/dev/shm";
  return std::filesystem::temp_directory_path().string();
}

// A file for a recording, removed after.
struct TmpfsFile {
  explicit TmpfsFile(const std::string& what) : path{folder() + "/" + new_name(what) + ".mcap"} {}
  ~TmpfsFile() { std::filesystem::remove(path); }
  std::string path;
};

// The publisher on the first CPU, the recorder on the others: "a publisher
// flat out on another core". On one CPU, all share it.
cpu_set_t cpus(bool publisher) {
  cpu_set_t set;
  CPU_ZERO(&set);
  const auto n = std::max(1u, std::thread::hardware_concurrency());
  if (n == 1) {
    CPU_SET(0, &set);
    return set;
  }
  if (publisher) CPU_SET(0, &set);
  for (unsigned c = 1; !publisher && c < n; ++c) CPU_SET(c, &set);
  return set;
}
void pin_this_thread_as_publisher() {
  const auto set = cpus(true);
  ::sched_setaffinity(0, sizeof set, &set);
}
void unpin_this_thread() {
  cpu_set_t set;
  CPU_ZERO(&set);
  for (unsigned c = 0; c < std::max(1u, std::thread::hardware_concurrency()); ++c) CPU_SET(c, &set);
  ::sched_setaffinity(0, sizeof set, &set);
}

// `prime record` of `topic` in `domain` into `file`, until stop().
class Recorder {
 public:
  Recorder(shm::Core& core, const std::string& domain, const std::string& topic, const std::string& file)
      : child_{tool(), {tool(), "--domain", domain, "record", topic, "-o", file, "--compression", "none"},
               {.inherit_fds = {}, .cpus = cpus(false), .output_fd = -1}} {
    // Joined: then it opens its reader at once, from the head on; what it
    // missed before is neither recorded nor lost.
    const auto deadline = Clock::now() + 10s;
    while (Clock::now() < deadline) {
      for (const auto& p : core.registry().participants)
        if (p.name == "prime record" && p.alive && p.pid == static_cast<std::uint32_t>(child_.pid())) return;
      if (child_.poll()) break;
      std::this_thread::yield();
    }
    throw std::runtime_error{"prime record did not join"};
  }
  // Ctrl-C: it writes what it queued, closes the file and exits.
  void stop() {
    child_.signal(SIGINT);
    const auto status = child_.wait_for(60s);
    if (!status || !WIFEXITED(*status) || WEXITSTATUS(*status) != 0)
      throw std::runtime_error{"prime record " + (status ? prime::bench::ipc::ChildProcess::describe(*status) : "did not end")};
  }

 private:
  prime::bench::ipc::ChildProcess child_;
};

struct Recorded {
  std::uint64_t messages = 0, lost = 0;
  double seconds = 0;        // from its first log time to its last
  std::uint64_t first = 0;   // the sequence number in its first sample: from there on, every one is recorded or lost
};
Recorded recorded_in(const std::string& file, const std::string& topic) {
  rec::McapReader reader{file};
  const auto& s = reader.summary();
  Recorded r;
  if (!s.chunks.empty()) {
    bool seen = false;
    reader.for_each_message_in(s.chunks.front(), [&](const rec::Message& m) {
      if (!seen && m.data.size() >= sizeof r.first) std::memcpy(&r.first, m.data.data(), sizeof r.first);
      seen = true;
    });
  }
  r.messages = s.statistics.message_count;
  r.seconds = static_cast<double>(s.statistics.message_end_time - s.statistics.message_start_time) / 1e9;
  for (const auto& m : s.metadata)
    if (m.name == rec::kLossesMetadata && m.values.contains(topic)) r.lost = std::stoull(m.values.at(topic));
  return r;
}

// Publishes flat out for `seconds`; samples per second.
template <class T>
double publish_flat_out(shm::Publisher<T>& publisher, double seconds) {
  const auto until = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds));
  std::uint64_t n = 0;
  const auto start = Clock::now();
  for (;;) {
    for (int k = 0; k < 64; ++k) {
      auto loan = publisher.loan();
      if (!loan) throw std::runtime_error{loan.error().message};
      (*loan)->seq = n++;
      std::move(*loan).publish();
    }
    if (Clock::now() >= until) break;
  }
  return static_cast<double>(n) / std::chrono::duration<double>(Clock::now() - start).count();
}

template <std::size_t N>
void BM_RecordFlat(benchmark::State& state) {
  const auto domain = new_name("record");
  shm::Core core{domain};
  auto publisher = core.publisher<Blob<N>>("bench/flat");
  TmpfsFile file{"flat"};
  for (auto _ : state) {
    Recorder recorder{core, domain, "bench/flat", file.path};
    pin_this_thread_as_publisher();
    const auto published = publish_flat_out(publisher, seconds_per_run());
    unpin_this_thread();
    recorder.stop();
    const auto r = recorded_in(file.path, "bench/flat");
    state.counters["published_per_s"] = published;
    state.counters["recorded_per_s"] = r.seconds > 0 ? static_cast<double>(r.messages) / r.seconds : 0;
    state.counters["recorded_bytes_per_s"] = r.seconds > 0 ? static_cast<double>(r.messages * N) / r.seconds : 0;
    state.counters["lost"] = static_cast<double>(r.lost);
  }
}

template <std::size_t N>
void BM_PublisherAlone(benchmark::State& state) {
  shm::Core core{new_name("alone")};
  auto publisher = core.publisher<Blob<N>>("bench/flat");
  for (auto _ : state) {
    pin_this_thread_as_publisher();
    state.counters["published_per_s"] = publish_flat_out(publisher, seconds_per_run());
    unpin_this_thread();
  }
}

template <std::size_t N>
void BM_PublisherBesideReader(benchmark::State& state) {
  shm::Core core{new_name("beside")};
  auto publisher = core.publisher<Blob<N>>("bench/flat");
  auto reader = core.subscribe<Blob<N>>("bench/flat").subscribe();
  for (auto _ : state) {
    std::atomic<bool> done{false};
    std::uint64_t read = 0;
    std::thread reading{[&] {
      const auto set = cpus(false);
      ::sched_setaffinity(0, sizeof set, &set);
      while (!done.load(std::memory_order_relaxed))
        if (auto s = reader.try_read()) {
          benchmark::DoNotOptimize(s->value->seq);  // its payload read, as a recorder's is
          ++read;
        }
    }};
    pin_this_thread_as_publisher();
    const auto start = Clock::now();
    state.counters["published_per_s"] = publish_flat_out(publisher, seconds_per_run());
    const auto took = std::chrono::duration<double>(Clock::now() - start).count();
    unpin_this_thread();
    done = true;
    reading.join();
    state.counters["read_per_s"] = static_cast<double>(read) / took;
  }
}

// Publishes at `hz` for the run's seconds, each sample at its time (the
// clock read between), on the publisher's CPU: how many, at what rate,
// and the mean time a loan and publish took.
struct Paced {
  std::uint64_t count;
  double rate;
  double publish_ns;      // the mean
  double publish_p50_ns;  // the median: what a preempted publish or two leave alone
};
template <class T>
Paced publish_paced(shm::Publisher<T>& publisher, double hz) {
  pin_this_thread_as_publisher();
  const auto period = std::chrono::duration<double>(1.0 / hz);
  const auto count = static_cast<std::uint64_t>(hz * seconds_per_run());
  std::vector<Clock::duration> took(count);
  const auto start = Clock::now();
  for (std::uint64_t i = 0; i < count; ++i) {
    const auto due = start + std::chrono::duration_cast<Clock::duration>(period * static_cast<double>(i));
    while (Clock::now() < due) {
    }
    const auto before = Clock::now();
    auto loan = publisher.loan();
    if (!loan) throw std::runtime_error{loan.error().message};
    (*loan)->seq = i;
    std::move(*loan).publish();
    took[i] = Clock::now() - before;
  }
  const auto seconds = std::chrono::duration<double>(Clock::now() - start).count();
  unpin_this_thread();
  Clock::duration publishing{};
  for (const auto t : took) publishing += t;
  std::ranges::nth_element(took, took.begin() + static_cast<std::ptrdiff_t>(count / 2));
  auto ns = [](Clock::duration d) { return std::chrono::duration<double, std::nano>(d).count(); };
  return {count, static_cast<double>(count) / seconds, ns(publishing) / static_cast<double>(count), ns(took[count / 2])};
}

// The same publisher with no recorder: what a loan and publish take alone.
template <std::size_t N>
void BM_PublishPacedAlone(benchmark::State& state) {
  shm::Core core{new_name("paced-alone")};
  auto publisher = core.publisher<Blob<N>>("bench/paced", {.capacity = static_cast<std::size_t>(state.range(1))});
  for (auto _ : state) {
    const auto p = publish_paced(publisher, static_cast<double>(state.range(0)));
    state.counters["published_per_s"] = p.rate;
    state.counters["publish_ns"] = p.publish_ns;
    state.counters["publish_p50_ns"] = p.publish_p50_ns;
  }
}

// A publisher at `hz` on a ring `capacity` deep: what the recorder took of what was
// published from its first sample on, and what it lost; `missing` is what
// is neither (none, or the accounting is wrong).
template <std::size_t N>
void BM_RecordPaced(benchmark::State& state) {
  const auto hz = static_cast<double>(state.range(0));
  const auto domain = new_name("paced");
  shm::Core core{domain};
  auto publisher = core.publisher<Blob<N>>("bench/paced", {.capacity = static_cast<std::size_t>(state.range(1))});
  TmpfsFile file{"paced"};
  for (auto _ : state) {
    Recorder recorder{core, domain, "bench/paced", file.path};
    const auto [count, rate, publish_ns, publish_p50_ns] = publish_paced(publisher, hz);
    recorder.stop();
    const auto r = recorded_in(file.path, "bench/paced");
    const auto after_first = count - r.first;
    state.counters["published_per_s"] = rate;
    state.counters["publish_ns"] = publish_ns;
    state.counters["publish_p50_ns"] = publish_p50_ns;
    state.counters["published_from_first"] = static_cast<double>(after_first);
    state.counters["recorded"] = static_cast<double>(r.messages);
    state.counters["lost"] = static_cast<double>(r.lost);
    state.counters["missing"] = static_cast<double>(after_first) - static_cast<double>(r.messages + r.lost);
  }
}

// A recording of 2 s at 1 kHz, made here, played by `prime play` into a
// topic this process reads busily: each sample's arrival after the first's,
// against its log time after the first's.
void BM_PlayTiming(benchmark::State& state) {
  using Sample = Blob<64>;
  constexpr std::uint64_t kCount = 2000, kPeriodNs = 1'000'000;
  TmpfsFile file{"play"};
  {
    rec::McapWriter w{file.path, {.compression = rec::Compression::none, .chunk_size = 1 << 20, .profile = ""}};
    const auto type = prime::Fingerprint::of<Sample>();
    auto metadata = rec::fingerprint_metadata(type);
    metadata["capacity"] = "64";
    const auto channel = w.add_channel(w.add_schema(type.describe(), "prime", ""), "bench/played", "prime-raw", metadata);
    Sample s{};
    for (std::uint64_t i = 0; i < kCount; ++i) {
      s.seq = i;
      w.write(channel, static_cast<std::uint32_t>(i), 1'000'000'000 + i * kPeriodNs, 0,
              std::as_bytes(std::span{&s, 1}));
    }
  }
  for (auto _ : state) {
    const auto domain = new_name("play");
    shm::Core core{domain};
    auto reader = core.subscribe<Sample>("bench/played", {}, {.capacity = 1024, .overflow = prime::Overflow::block}).subscribe();
    prime::bench::ipc::ChildProcess play{tool(), {tool(), "--domain", domain, "play", file.path}, {}};
    std::vector<Clock::time_point> arrived;
    arrived.reserve(kCount);
    const auto give_up = Clock::now() + 30s;
    while (arrived.size() < kCount && Clock::now() < give_up)
      if (auto s = reader.try_read()) arrived.push_back(Clock::now());
    play.wait_for(10s);
    if (arrived.size() < kCount) {
      state.SkipWithError("prime play delivered too few samples");
      return;
    }
    std::vector<double> error;
    for (std::uint64_t i = 0; i < kCount; ++i)
      error.push_back(std::abs(std::chrono::duration<double, std::nano>(arrived[i] - arrived[0]).count() -
                               static_cast<double>(i * kPeriodNs)));
    std::ranges::sort(error);
    state.counters["timing_error_p50_ns"] = error[error.size() / 2];
    state.counters["timing_error_p99_ns"] = error[error.size() * 99 / 100];
    state.counters["timing_error_max_ns"] = error.back();
  }
}

// The floor a recorder of 1 MiB samples cannot beat: write() of 1 MiB
// blocks into a new file in the same folder, on the recorder's CPUs, for
// the run's seconds (what `dd bs=1M` does): bytes per second.
void BM_WriteFloor(benchmark::State& state) {
  TmpfsFile file{"floor"};
  std::vector<std::byte> block(1 << 20, std::byte{0x5a});
  for (auto _ : state) {
    const auto set = cpus(false);
    ::sched_setaffinity(0, sizeof set, &set);
    const int fd = ::open(file.path.c_str(), O_WRONLY | O_CREAT | O_TRUNC | O_CLOEXEC, 0600);
    if (fd < 0) throw std::runtime_error{"cannot make " + file.path};
    const auto until = Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(seconds_per_run()));
    const auto start = Clock::now();
    std::uint64_t written = 0;
    while (Clock::now() < until) {
      const auto n = ::write(fd, block.data(), block.size());
      if (n <= 0) break;
      written += static_cast<std::uint64_t>(n);
    }
    const auto took = std::chrono::duration<double>(Clock::now() - start).count();
    ::close(fd);
    std::filesystem::remove(file.path);
    unpin_this_thread();
    state.counters["written_bytes_per_s"] = static_cast<double>(written) / took;
  }
}

BENCHMARK(BM_WriteFloor)->Iterations(1)->UseRealTime();
BENCHMARK(BM_RecordFlat<64>)->Name("BM_RecordFlat/64")->Iterations(1)->UseRealTime();
BENCHMARK(BM_RecordFlat<1 << 20>)->Name("BM_RecordFlat/1048576")->Iterations(1)->UseRealTime();
BENCHMARK(BM_PublisherAlone<64>)->Name("BM_PublisherAlone/64")->Iterations(1)->UseRealTime();
BENCHMARK(BM_PublisherAlone<1 << 20>)->Name("BM_PublisherAlone/1048576")->Iterations(1)->UseRealTime();
BENCHMARK(BM_PublisherBesideReader<64>)->Name("BM_PublisherBesideReader/64")->Iterations(1)->UseRealTime();
BENCHMARK(BM_RecordPaced<64>)->Name("BM_RecordPaced/64")->Args({100'000, 64})->Args({100'000, 1024})->Iterations(1)->UseRealTime();
BENCHMARK(BM_PublishPacedAlone<64>)->Name("BM_PublishPacedAlone/64")->Args({100'000, 64})->Iterations(1)->UseRealTime();
BENCHMARK(BM_RecordPaced<1 << 20>)->Name("BM_RecordPaced/1048576")->Args({1'000, 64})->Iterations(1)->UseRealTime();
BENCHMARK(BM_PlayTiming)->Iterations(1)->UseRealTime();

}  // namespace

BENCHMARK_MAIN();
