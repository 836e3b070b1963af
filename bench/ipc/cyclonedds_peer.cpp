// CycloneDds: Eclipse Cyclone DDS 0.10 (Debian's cyclonedds), the other DDS
// ROS 2 ships, through its shared-memory path: iceoryx, served by the RouDi
// this benchmark starts (iceoryx_runtime.hpp), the one the Iceoryx peer uses.
// Cyclone takes that path between two processes of one machine when the
// configuration enables it (SharedMemory/Enable), the type is of fixed size
// and the QoS allows it (KEEP_LAST, VOLATILE or TRANSIENT_LOCAL, no
// deadline...); discovery still runs over UDP. Both configurations loan each
// sample from iceoryx (dds_loan_sample), stamp it and write it: dds_write
// hands the chunk over. They differ in how the reader reads:
//
//   CycloneDdsShm   dds_take() with a loan (a null buffer), as Cyclone's
//                   C API offers it: the loan is a buffer of the reader's own,
//                   into which Cyclone copies the chunk's N bytes (seen: the
//                   buffer is on the heap, and 1 MiB took 3x the time of
//                   64 B). Then the loan goes back (dds_return_loan).
//   CycloneDdsLoan  zero copy: the reader takes the sample's serialized form
//                   (dds_takecdr), which for a sample that came through
//                   iceoryx holds the chunk itself (ddsi_serdata::iox_chunk;
//                   ROS 2's rmw_cyclonedds takes a loaned message so), reads
//                   the number in place and drops it, which releases the
//                   chunk. The other N - 8 bytes are never touched. A sample
//                   without a chunk fails the run: it came by UDP.
//
//   Latency      the parent writes on `ping`, the child busy-polls the take
//                and answers with N bytes on `pong`, which the parent
//                busy-polls. RELIABLE, KEEP_LAST 1: one message is in flight
//                at a time.
//
// No throughput: this path cannot stream losslessly. It requires KEEP_LAST
// (a KEEP_ALL endpoint goes over UDP instead); the reader's iceoryx queue,
// as deep as its history, drops its oldest chunk when full, as Cyclone's
// writer never waits for it; and the reader's history drops its oldest
// sample beyond its depth. A writer faster than its reader loses samples, by
// design (tried: a 64 B stream, 256 deep, lost 94 % of them). `prime bench`
// lists the row as skipped, with this reason.
//
// As with Fast DDS, each sample passes a thread of the reader's process:
// Cyclone's iceoryx listener wakes on the chunk and stores it in the reader's
// history, where the take finds it. That thread shares the poller's CPU.
//
// The sample type is a topic descriptor of our own per payload size (an
// array of N octets, no key), not idlc's: one template instead of generated
// C for five IDL structs. It carries no type information, so discovery
// matches the two ends by type name.
//
// Each benchmark run has its own domain, made with dds_create_domain() and
// the configuration below (CYCLONEDDS_URI's syntax, so that the environment's
// CYCLONEDDS_URI plays no part), in each process, after the child is spawned
// (Cyclone's threads run on their process's CPU); its own domain id and topic
// names, from the parent's pid and the run. The child's iceoryx runtime is
// named after the run (iceoryx_runtime.hpp), before Cyclone asks for one
// (iceoryx's runtime is one per process: Cyclone's request returns ours), so
// the parent can remove what a killed child leaves in /tmp.

#include <unistd.h>

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <thread>
#include <utility>

#include <dds/dds.h>
#include <dds/ddsc/dds_loan_api.h>
#include <dds/ddsi/ddsi_serdata.h>
#include <dds/ddsi/ddsi_shm_transport.h>

#include "harness.hpp"
#include "iceoryx_runtime.hpp"
#include "payload.hpp"
#include "sample_sizes.hpp"

namespace {

namespace ipc = prime::bench::ipc;
using ipc::iceoryx::ChildRuntimeFiles;

// ---- the sample type ----------------------------------------------------------

// `struct { octet data[N]; }`: fixed size, so Cyclone loans it from iceoryx
// and hands it over as it is, with no serialization. Built on first use (the
// statics of a template are initialised in no set order).
template <std::size_t N>
const dds_topic_descriptor_t& descriptor() {
  constexpr auto op = [](auto code) { return static_cast<std::uint32_t>(code); };  // the codes are of three enums
  static constexpr std::uint32_t kOps[] = {op(DDS_OP_ADR) | op(DDS_OP_TYPE_ARR) | op(DDS_OP_SUBTYPE_1BY), 0,
                                           static_cast<std::uint32_t>(N), op(DDS_OP_RTS)};
  static const std::string name = "PrimeIpcBytes" + std::to_string(N);
  static const dds_topic_descriptor_t descriptor{
      .m_size = static_cast<std::uint32_t>(N),
      .m_align = 1,
      .m_flagset = DDS_TOPIC_FIXED_SIZE,
      .m_nkeys = 0,
      .m_typename = name.c_str(),
      .m_keys = nullptr,
      .m_nops = 2,  // instructions, not words: the array's and the return
      .m_ops = kOps,
      .m_meta = "",
      .type_information = {nullptr, 0},
      .type_mapping = {nullptr, 0},
      .restrict_data_representation = 0,
  };
  return descriptor;
}

// ---- configuration ------------------------------------------------------------

// Shared memory on, and iceoryx's log (its own) down to warnings.
constexpr const char* kConfig =
    "<CycloneDDS><Domain id=\"any\">"
    "<SharedMemory><Enable>true</Enable><LogLevel>warn</LogLevel></SharedMemory>"
    "</Domain></CycloneDDS>";

enum class Mode { kShm, kLoan };

constexpr const char* peer_name(Mode mode) { return mode == Mode::kShm ? "CycloneDdsShm" : "CycloneDdsLoan"; }
std::string entry(Mode mode, const char* role) { return std::string{peer_name(mode)} + "." + role; }

// Answered, but not counted: the parent's first messages (see await_iceoryx()).
constexpr std::uint64_t kProbe = 0;

// Cyclone says why an operation failed in its log, not in the code it returns
// (a bad configuration is "Error (-1)"). Its errors are kept here, so that a
// failure's message can carry the last one, and all it logs still goes to
// stderr.
class ErrorLog {
 public:
  static ErrorLog& instance() {
    static ErrorLog log;
    return log;
  }
  ErrorLog(const ErrorLog&) = delete;
  ErrorLog& operator=(const ErrorLog&) = delete;
  // Back to Cyclone's sink: its library may log after this is gone.
  ~ErrorLog() { dds_set_log_sink(nullptr, nullptr); }

  // The last error since the last call, if any. Thread-safe.
  std::string take() {
    const std::lock_guard lock{mutex_};
    return std::exchange(last_, {});
  }

 private:
  ErrorLog() { dds_set_log_sink(&ErrorLog::write, this); }

  static void write(void* self, const dds_log_data_t* data) {
    std::string text{data->message, data->size};  // a line, without its time stamp
    while (!text.empty() && text.back() == '\n') text.pop_back();
    std::fprintf(stderr, "Cyclone DDS: %s\n", text.c_str());
    if ((data->priority & (DDS_LC_FATAL | DDS_LC_ERROR)) == 0) return;
    auto& log = *static_cast<ErrorLog*>(self);
    const std::lock_guard lock{log.mutex_};
    log.last_ = std::move(text);
  }

  std::mutex mutex_;
  std::string last_;
};

[[noreturn]] void fail(const std::string& what, dds_return_t code) {
  std::string message = "Cyclone DDS: " + what + " failed: " + dds_strretcode(code) + " (" + std::to_string(code) + ")";
  if (const std::string why = ErrorLog::instance().take(); !why.empty()) message += ": " + why;
  throw ipc::PeerError{message};
}

dds_entity_t check(dds_entity_t entity, const std::string& what) {
  if (entity < 0) fail(what, entity);
  return entity;
}

// One run's names: its domain id, and the run's own name ("<pid>-<n>"),
// which names the child's iceoryx runtime and the run's topics.
struct Names {
  int domain;
  std::string run;
};

// The topic `what` of run `run` (DDS allows no '-' in a topic's name).
std::string topic_name(std::string run, const char* what) {
  std::replace(run.begin(), run.end(), '-', '_');
  return "prime_ipc_" + run + "_" + what;
}

// A domain id from the parent's pid and the run, as the Fast DDS peer's: 1 to
// 230, the ids whose ports fit Cyclone's default port mapping.
Names new_names() {
  static std::atomic<int> next{0};
  return {1 + (::getpid() + next++) % 230, ipc::iceoryx::new_topic()};
}

// The domain `id`, configured by kConfig. Errors logged before it are another
// run's: forgotten.
dds_entity_t create_domain(int id) {
  (void)ErrorLog::instance().take();
  return check(dds_create_domain(static_cast<dds_domainid_t>(id), kConfig), "dds_create_domain");
}

// ---- a domain -------------------------------------------------------------------

// One process's domain, with a participant and endpoints of the sample type of
// N bytes; deletes all of it, and with it its iceoryx ports, when it goes.
template <std::size_t N>
class Domain {
 public:
  explicit Domain(int id) : domain_{create_domain(id)} {
    try {
      participant_ = check(dds_create_participant(static_cast<dds_domainid_t>(id), nullptr, nullptr),
                           "dds_create_participant");
      qos_.reset(dds_create_qos());
      dds_qset_reliability(qos_.get(), DDS_RELIABILITY_RELIABLE, DDS_SECS(1));
      dds_qset_durability(qos_.get(), DDS_DURABILITY_VOLATILE);
      dds_qset_history(qos_.get(), DDS_HISTORY_KEEP_LAST, 1);
    } catch (...) {
      dds_delete(domain_);
      throw;
    }
  }
  Domain(const Domain&) = delete;
  Domain& operator=(const Domain&) = delete;
  ~Domain() { dds_delete(domain_); }

  dds_entity_t writer(const std::string& name) {
    const dds_entity_t writer = check(dds_create_writer(participant_, topic(name), qos_.get(), nullptr),
                                      "dds_create_writer on " + name);
    // Refused, not measured: without these the row would be of Cyclone's UDP path.
    if (!dds_is_shared_memory_available(writer) || !dds_is_loan_available(writer))
      throw ipc::PeerError{"Cyclone DDS: the writer on " + name + " has no shared memory (iceoryx) to loan from"};
    return writer;
  }

  dds_entity_t reader(const std::string& name) {
    const dds_entity_t reader = check(dds_create_reader(participant_, topic(name), qos_.get(), nullptr),
                                      "dds_create_reader on " + name);
    if (!dds_is_shared_memory_available(reader))
      throw ipc::PeerError{"Cyclone DDS: the reader on " + name + " has no shared memory (iceoryx) to read from"};
    return reader;
  }

 private:
  dds_entity_t topic(const std::string& name) {
    return check(dds_create_topic(participant_, &descriptor<N>(), name.c_str(), nullptr, nullptr),
                 "dds_create_topic " + name);
  }

  struct QosDeleter {
    void operator()(dds_qos_t* qos) const { dds_delete_qos(qos); }
  };

  dds_entity_t domain_;
  dds_entity_t participant_ = 0;
  std::unique_ptr<dds_qos_t, QosDeleter> qos_;
};

bool matched_writer(dds_entity_t writer) {
  dds_publication_matched_status_t status;
  return dds_get_publication_matched_status(writer, &status) == DDS_RETCODE_OK && status.current_count > 0;
}

bool matched_reader(dds_entity_t reader) {
  dds_subscription_matched_status_t status;
  return dds_get_subscription_matched_status(reader, &status) == DDS_RETCODE_OK && status.current_count > 0;
}

// ---- messages -----------------------------------------------------------------

// Loans a sample, writes `seq` into it and writes it. With one message in
// flight the pool is never short of chunks, so a failed loan is a failure.
void send(dds_entity_t writer, std::uint64_t seq) {
  void* sample = nullptr;
  if (const dds_return_t code = dds_loan_sample(writer, &sample); code != DDS_RETCODE_OK)
    fail("dds_loan_sample", code);
  ipc::stamp(sample, seq);
  if (const dds_return_t code = dds_write(writer, sample); code != DDS_RETCODE_OK) fail("dds_write of a loan", code);
}

// CycloneDdsShm: takes the next sample with a loan, if there is one, and
// returns the loan: its number, or nothing if there was none (or only news of
// a writer).
std::optional<std::uint64_t> take_copied(dds_entity_t reader) {
  void* samples[1] = {nullptr};
  dds_sample_info_t infos[1];
  const dds_return_t n = dds_take(reader, samples, infos, 1, 1);
  if (n == 0) return std::nullopt;
  if (n < 0) fail("dds_take", n);
  const bool valid = infos[0].valid_data;
  const std::uint64_t seq = valid ? ipc::seq_of(samples[0]) : 0;
  if (const dds_return_t code = dds_return_loan(reader, samples, n); code != DDS_RETCODE_OK)
    fail("dds_return_loan", code);
  if (!valid) return std::nullopt;
  return seq;
}

// CycloneDdsLoan: the same, reading the number in the sample's iceoryx chunk.
std::optional<std::uint64_t> take_in_place(dds_entity_t reader) {
  ddsi_serdata* data = nullptr;
  dds_sample_info_t info;
  const dds_return_t n = dds_takecdr(reader, &data, 1, &info, DDS_ANY_STATE);
  if (n == 0) return std::nullopt;
  if (n < 0) fail("dds_takecdr", n);
  const std::unique_ptr<ddsi_serdata, decltype(&ddsi_serdata_unref)> held{data, &ddsi_serdata_unref};
  if (!info.valid_data) return std::nullopt;
  if (data->iox_chunk == nullptr)
    throw ipc::PeerError{"Cyclone DDS: a sample came by UDP, not through shared memory"};
  if (iceoryx_header_from_chunk(data->iox_chunk)->shm_data_state != IOX_CHUNK_CONTAINS_RAW_DATA)
    throw ipc::PeerError{"Cyclone DDS: a sample's chunk holds serialized data, not the sample"};
  return ipc::seq_of(data->iox_chunk);
}

template <Mode kMode>
std::optional<std::uint64_t> take(dds_entity_t reader) {
  if constexpr (kMode == Mode::kShm) return take_copied(reader);
  else return take_in_place(reader);
}

// The parent's: takes the answer carrying `seq`, if it is in; passes over the
// answers to probes.
template <Mode kMode>
bool try_take(dds_entity_t reader, std::uint64_t seq) {
  const auto got = take<kMode>(reader);
  if (!got || *got == kProbe) return false;
  if (*got != seq) throw ipc::out_of_sequence(seq, *got);
  return true;
}

// Cyclone's discovery matches writer and reader before RouDi has connected
// their iceoryx ports, and a VOLATILE sample written in between reaches no
// one. So, before the round trips, the parent writes probes, one a
// millisecond, until the child answers one.
template <Mode kMode>
void await_iceoryx(ipc::Link& child, dds_entity_t ping, dds_entity_t pong) {
  ipc::Patience<ipc::Link> patience{child};
  for (;;) {
    send(ping, kProbe);
    for (int i = 0; i < 10; ++i) {
      if (const auto got = take<kMode>(pong); got && *got == kProbe) return;
      std::this_thread::sleep_for(std::chrono::microseconds{100});
    }
    patience.idle();
  }
}

// ---- the child ------------------------------------------------------------------

// arg(0): the run's name, arg(1): the domain id.
template <Mode kMode>
void echo(ipc::Child& self) {
  ipc::with_sample_size(self.bytes(), "Cyclone DDS", [&]<std::size_t N>() {
    ipc::iceoryx::start_child_runtime(self.arg(0));
    Domain<N> domain{std::stoi(self.arg(1))};
    const dds_entity_t ping = domain.reader(topic_name(self.arg(0), "ping"));
    const dds_entity_t pong = domain.writer(topic_name(self.arg(0), "pong"));
    ipc::sleep_until(self, [&] { return matched_reader(ping) && matched_writer(pong); });
    self.ready();
    for (std::uint64_t seq = 1;;) {
      std::optional<std::uint64_t> got;
      ipc::spin_until(self, [&] { return (got = take<kMode>(ping)).has_value(); });
      if (*got == kProbe) {
        send(pong, kProbe);
        continue;
      }
      if (*got != seq) throw ipc::out_of_sequence(seq, *got);
      send(pong, seq++);
    }
  });
}
const ipc::ChildEntry kShmEcho{"CycloneDdsShm.echo", echo<Mode::kShm>};
const ipc::ChildEntry kLoanEcho{"CycloneDdsLoan.echo", echo<Mode::kLoan>};

// ---- the parent ---------------------------------------------------------------------

// The parent's domain is made once the child is spawned (the Link pins this
// thread to its CPU, and Cyclone's threads inherit that), but declared
// before the Link: the child is gone before it goes.
template <Mode kMode>
void latency(benchmark::State& state) {
  ipc::iceoryx::run_on_roudi(state, [&](std::size_t bytes) {
    ipc::with_sample_size(bytes, "Cyclone DDS", [&]<std::size_t N>() {
      const Names names = new_names();
      std::optional<Domain<N>> domain;
      const ChildRuntimeFiles files{names.run};
      ipc::Link child{entry(kMode, "echo"), N, {}, {names.run, std::to_string(names.domain)}};
      domain.emplace(names.domain);
      const dds_entity_t ping = domain->writer(topic_name(names.run, "ping"));
      const dds_entity_t pong = domain->reader(topic_name(names.run, "pong"));
      child.wait_ready();
      ipc::sleep_until(child, [&] { return matched_writer(ping) && matched_reader(pong); });
      child.go();
      await_iceoryx<kMode>(child, ping, pong);
      ipc::time_round_trips(state, [&](std::uint64_t seq) {
        send(ping, seq);
        ipc::spin_until(child, [&] { return try_take<kMode>(pong, seq); });
      });
      child.stop();
    });
  });
}

void BM_Latency_CycloneDdsShm(benchmark::State& state) { latency<Mode::kShm>(state); }
void BM_Latency_CycloneDdsLoan(benchmark::State& state) { latency<Mode::kLoan>(state); }
BENCHMARK(BM_Latency_CycloneDdsShm)->Apply(ipc::latency_payloads);
BENCHMARK(BM_Latency_CycloneDdsLoan)->Apply(ipc::latency_payloads);

}  // namespace
