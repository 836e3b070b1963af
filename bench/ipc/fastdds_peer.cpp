// FastDds: eProsima Fast DDS 2.9 (Debian's libfastrtps), the default DDS of
// ROS 2, in the two shared-memory configurations its users know:
//
//   FastDdsShm    the shared-memory transport only (the builtin UDP transports
//                 off) and a plain write() of an N-byte ipc::Payload: Fast DDS
//                 serializes it (a memcpy) into its history, the transport
//                 copies it into the writer's segment, the reader's receive
//                 thread copies it into the reader's history, and
//                 take_next_sample() copies it out into the reader's Payload.
//   FastDdsLoan   data sharing, zero copy: the writer loans an N-byte sample
//                 in its shared-memory pool (loan_sample), stamps it and
//                 writes it; the reader takes it in place (take() into a
//                 loaned LoanableSequence), reads the number and returns the
//                 loan. The other N - 8 bytes are never touched. The
//                 shared-memory transport carries only discovery, heartbeats,
//                 acknowledgements and the data-sharing notifications.
//
//   Latency      the parent writes on `ping`, the child busy-polls take() and
//                answers with N bytes on `pong`, which the parent busy-polls.
//                RELIABLE, KEEP_LAST 1: one message is in flight at a time.
//   Throughput   the child writes back-to-back; RELIABLE, KEEP_ALL with room
//                for kStreamDepth samples on both sides, so a full history
//                makes write() wait for acknowledgements (for at most
//                max_blocking_time, then it tries again) and nothing is lost;
//                the parent busy-polls take(), one sample per iteration.
//
// Busy polling, no WaitSet and no listener: the application threads poll
// take(). Fast DDS still puts each sample into the reader's history on a
// thread of its own, which sleeps until woken: the transport's receive thread
// (FastDdsShm) or the data-sharing listener (FastDdsLoan). That thread shares
// its process's CPU with the poller (the harness pins each process to one
// CPU), so every one-way trip includes a thread wake-up on a busy CPU. That
// is Fast DDS's design: a ROS 2 node's executor waits on the same hand-off.
//
// The sample type is our own TopicDataType per payload size (SampleType<N>:
// N bytes, plain and bounded, serialized with memcpy), not fastddsgen's, so a
// benchmark runs only at the sizes for which one is compiled: the sizes of
// kLatencyPayloads and kThroughputPayloads.
//
// Each benchmark run has its own two participants (one per process, created
// after the child is spawned, so Fast DDS's threads run on that process's
// CPU), its own domain and topics named after the parent's pid and the run,
// so concurrent prime_ipc runs do not cross. Every payload size works in both
// configurations: nothing is skipped.
//
// /dev/shm: a participant deleted in the normal way removes everything it made
// there (fastrtps_* segments and ports, fast_datasharing_* pools), checked
// after full runs; a process that is killed leaves its files behind.

#include <unistd.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cstddef>
#include <cstdint>
#include <cstring>
#include <functional>
#include <iterator>
#include <memory>
#include <optional>
#include <string>
#include <type_traits>
#include <utility>

#include <fastdds/dds/core/LoanableSequence.hpp>
#include <fastdds/dds/domain/DomainParticipant.hpp>
#include <fastdds/dds/domain/DomainParticipantFactory.hpp>
#include <fastdds/dds/domain/qos/DomainParticipantQos.hpp>
#include <fastdds/dds/publisher/DataWriter.hpp>
#include <fastdds/dds/publisher/Publisher.hpp>
#include <fastdds/dds/publisher/qos/DataWriterQos.hpp>
#include <fastdds/dds/publisher/qos/PublisherQos.hpp>
#include <fastdds/dds/subscriber/DataReader.hpp>
#include <fastdds/dds/subscriber/SampleInfo.hpp>
#include <fastdds/dds/subscriber/Subscriber.hpp>
#include <fastdds/dds/subscriber/qos/DataReaderQos.hpp>
#include <fastdds/dds/subscriber/qos/SubscriberQos.hpp>
#include <fastdds/dds/topic/Topic.hpp>
#include <fastdds/dds/topic/TopicDataType.hpp>
#include <fastdds/dds/topic/TypeSupport.hpp>
#include <fastdds/dds/topic/qos/TopicQos.hpp>
#include <fastdds/rtps/common/SerializedPayload.h>
#include <fastdds/rtps/transport/shared_mem/SharedMemTransportDescriptor.h>

#include "harness.hpp"
#include "payload.hpp"
#include "sample_sizes.hpp"

namespace {

namespace ipc = prime::bench::ipc;
namespace dds = eprosima::fastdds::dds;
namespace rtps = eprosima::fastrtps::rtps;
using ReturnCode = eprosima::fastrtps::types::ReturnCode_t;

// ---- the sample type ---------------------------------------------------------

// A sample of N bytes: plain (its bytes are its serialized form) and bounded
// (always N bytes), as data sharing and loans require.
template <std::size_t N>
using Sample = std::array<std::byte, N>;

template <std::size_t N>
class SampleType final : public dds::TopicDataType {
 public:
  // The serialized form: the representation header (CDR, little endian),
  // then the N bytes.
  static constexpr std::uint32_t kHeader = rtps::SerializedPayload_t::representation_header_size;
  static constexpr std::uint32_t kSize = static_cast<std::uint32_t>(N) + kHeader;

  SampleType() {
    setName(("PrimeIpcBytes" + std::to_string(N)).c_str());
    m_typeSize = kSize;
    m_isGetKeyDefined = false;
    auto_fill_type_object(false);
    auto_fill_type_information(false);
  }

  bool serialize(void* data, rtps::SerializedPayload_t* payload) override {
    if (payload->max_size < kSize) return false;
    const std::uint8_t header[kHeader] = {0, CDR_LE, 0, 0};
    std::memcpy(payload->data, header, kHeader);
    std::memcpy(payload->data + kHeader, data, N);
    payload->encapsulation = CDR_LE;
    payload->length = kSize;
    return true;
  }

  bool deserialize(rtps::SerializedPayload_t* payload, void* data) override {
    if (payload->length < kSize) return false;
    std::memcpy(data, payload->data + kHeader, N);
    return true;
  }

  std::function<std::uint32_t()> getSerializedSizeProvider(void*) override {
    return [] { return kSize; };
  }

  void* createData() override { return new Sample<N>{}; }
  void deleteData(void* data) override { delete static_cast<Sample<N>*>(data); }

  // The topic has no key.
  bool getKey(void*, rtps::InstanceHandle_t*, bool) override { return false; }

  bool is_bounded() const override { return true; }
  bool is_plain() const override { return true; }
};

// A SampleType<N> for N == bytes (sample_sizes.hpp).
template <class F>
void with_sample_size(std::size_t bytes, F f) {
  ipc::with_sample_size(bytes, "Fast DDS", std::move(f));
}

// ---- configuration -----------------------------------------------------------

enum class Mode { kShm, kLoan };
enum class Flow { kPingPong, kStream };

[[noreturn]] void fail(const std::string& what, ReturnCode code) {
  throw ipc::PeerError{"Fast DDS: " + what + " failed (ReturnCode_t " + std::to_string(code()) + ")"};
}

// The shared-memory transport's segment, where a participant's outgoing
// messages wait for the readers' receive threads. When it is full, Fast DDS
// reclaims the oldest messages still waiting, and their reader loses them (a
// reliable writer sends them again, but only once a heartbeat has shown the
// gap). So FastDdsShm's holds every message a stream may have in flight (or
// four of a ping-pong): a message is a sample plus RTPS headers. FastDdsLoan
// sends only small messages and keeps Fast DDS's default, 512 KiB.
std::uint32_t segment_bytes(std::size_t bytes, Flow flow) {
  constexpr std::size_t kDefault = 512 << 10;
  const std::size_t messages = flow == Flow::kStream ? ipc::kStreamDepth + 4 : 4;
  return static_cast<std::uint32_t>(std::max(kDefault, messages * (bytes + (4 << 10))));
}

// The shared-memory transport and no other.
dds::DomainParticipantQos participant_qos(Mode mode, Flow flow, std::size_t bytes) {
  dds::DomainParticipantQos qos;
  qos.name("prime-ipc");
  auto shm = std::make_shared<eprosima::fastdds::rtps::SharedMemTransportDescriptor>();
  if (mode == Mode::kShm) shm->segment_size(segment_bytes(bytes, flow));
  qos.transport().use_builtin_transports = false;
  qos.transport().user_transports.push_back(std::move(shm));
  return qos;
}

// Both ends of a topic: reliable and volatile, the history and the data
// sharing of `mode` and `flow`. Data sharing must be off for FastDdsShm
// explicitly: Fast DDS turns it on by itself (AUTO) for a plain bounded type.
template <class Qos>
void configure(Qos& qos, Mode mode, Flow flow) {
  qos.reliability().kind = dds::RELIABLE_RELIABILITY_QOS;
  qos.durability().kind = dds::VOLATILE_DURABILITY_QOS;
  if (flow == Flow::kPingPong) {
    qos.history().kind = dds::KEEP_LAST_HISTORY_QOS;
    qos.history().depth = 1;
  } else {
    constexpr auto kDepth = static_cast<std::int32_t>(ipc::kStreamDepth);
    qos.history().kind = dds::KEEP_ALL_HISTORY_QOS;
    qos.resource_limits().max_samples = kDepth;
    qos.resource_limits().max_samples_per_instance = kDepth;
    qos.resource_limits().allocated_samples = kDepth;
    // A data-sharing writer reuses a sample of its pool as soon as the reader
    // has taken it, which is before the reader has read it: with as many
    // spare samples as the history holds, a freed one (the pool hands them
    // out first in, first out) is reused only kStreamDepth writes later.
    qos.resource_limits().extra_samples = kDepth;
  }
  // Data sharing needs a preallocated history; a bounded type's is anyway.
  qos.endpoint().history_memory_policy = rtps::PREALLOCATED_MEMORY_MODE;
  if (mode == Mode::kLoan) qos.data_sharing().on("");
  else qos.data_sharing().off();
}

// One run's names: its domain and the prefix of its topics.
struct Names {
  int domain;
  std::string topics;
};

// Each run has a domain of its own: one of the 232 that fit Fast DDS's port
// numbers (0, ROS 2's default, left out), counted on from the parent's pid.
// A run in the domain of the run before it, whose participants had just
// closed the same shared-memory ports, was slowed down by them twentyfold
// (a 1 MiB stream after a 64 B one: 32 msgs/s instead of about 800).
Names new_names() {
  static std::atomic<int> next{0};
  const int pid = ::getpid();
  const int run = next++;
  return {1 + (pid + run) % 232, "prime_ipc_" + std::to_string(pid) + "_" + std::to_string(run)};
}

// ---- a participant -------------------------------------------------------------

// One process's participant, with a publisher, a subscriber and the sample
// type of N bytes registered; deletes all of it (and with it its shared
// memory) when it goes.
template <std::size_t N>
class Participant {
 public:
  Participant(Mode mode, Flow flow, int domain) : mode_{mode}, flow_{flow} {
    participant_ = factory()->create_participant(static_cast<dds::DomainId_t>(domain), participant_qos(mode, flow, N));
    if (participant_ == nullptr) throw ipc::PeerError{"Fast DDS: cannot create a participant"};
    try {
      if (const auto code = type_.register_type(participant_); code != ReturnCode::RETCODE_OK)
        fail("register_type", code);
      publisher_ = participant_->create_publisher(dds::PublisherQos{});
      subscriber_ = participant_->create_subscriber(dds::SubscriberQos{});
      if (publisher_ == nullptr || subscriber_ == nullptr)
        throw ipc::PeerError{"Fast DDS: cannot create a publisher or a subscriber"};
    } catch (...) {
      destroy();
      throw;
    }
  }
  Participant(const Participant&) = delete;
  Participant& operator=(const Participant&) = delete;
  ~Participant() { destroy(); }

  dds::DataWriter& writer(const std::string& name) {
    dds::DataWriterQos qos;
    configure(qos, mode_, flow_);
    dds::DataWriter* writer = publisher_->create_datawriter(topic(name), qos);
    if (writer == nullptr) throw ipc::PeerError{"Fast DDS: cannot create a writer on " + name};
    return *writer;
  }

  dds::DataReader& reader(const std::string& name) {
    dds::DataReaderQos qos;
    configure(qos, mode_, flow_);
    dds::DataReader* reader = subscriber_->create_datareader(topic(name), qos);
    if (reader == nullptr) throw ipc::PeerError{"Fast DDS: cannot create a reader on " + name};
    return *reader;
  }

 private:
  static dds::DomainParticipantFactory* factory() { return dds::DomainParticipantFactory::get_instance(); }

  dds::Topic* topic(const std::string& name) {
    dds::Topic* topic = participant_->create_topic(name, type_.get_type_name(), dds::TopicQos{});
    if (topic == nullptr) throw ipc::PeerError{"Fast DDS: cannot create the topic " + name};
    return topic;
  }

  void destroy() noexcept {
    participant_->delete_contained_entities();
    factory()->delete_participant(participant_);
  }

  Mode mode_;
  Flow flow_;
  dds::TypeSupport type_{new SampleType<N>};
  dds::DomainParticipant* participant_ = nullptr;
  dds::Publisher* publisher_ = nullptr;
  dds::Subscriber* subscriber_ = nullptr;
};

bool matched(dds::DataWriter& writer) {
  dds::PublicationMatchedStatus status;
  return writer.get_publication_matched_status(status) == ReturnCode::RETCODE_OK && status.current_count > 0;
}

bool matched(dds::DataReader& reader) {
  dds::SubscriptionMatchedStatus status;
  return reader.get_subscription_matched_status(status) == ReturnCode::RETCODE_OK && status.current_count > 0;
}

// ---- messages ---------------------------------------------------------------------

// FastDdsShm: an N-byte Payload of this side's own, copied by write() and
// into by take_next_sample().
class Copies {
 public:
  explicit Copies(std::size_t bytes) : payload_{bytes} {}

  // Writes a message carrying `seq`, waiting while the writer's history is full.
  template <ipc::Side S>
  void send(S& side, dds::DataWriter& writer, std::uint64_t seq) {
    payload_.stamp(seq);
    ipc::Patience<S> patience{side};
    for (;;) {
      const auto code = writer.write(payload_.bytes().data(), dds::HANDLE_NIL);
      if (code == ReturnCode::RETCODE_OK) return;
      if (code != ReturnCode::RETCODE_TIMEOUT) fail("write", code);
      patience.idle();
    }
  }

  // Takes the next message, if there is one, and checks it carries `seq`.
  bool try_take(dds::DataReader& reader, std::uint64_t seq) {
    dds::SampleInfo info;
    const auto code = reader.take_next_sample(payload_.bytes().data(), &info);
    if (code == ReturnCode::RETCODE_NO_DATA) return false;
    if (code != ReturnCode::RETCODE_OK) fail("take_next_sample", code);
    if (!info.valid_data) return false;  // news of a writer, not a message
    if (const std::uint64_t got = payload_.seq(); got != seq) throw ipc::out_of_sequence(seq, got);
    return true;
  }

  void drain(dds::DataReader& reader) {
    dds::SampleInfo info;
    while (reader.take_next_sample(payload_.bytes().data(), &info) == ReturnCode::RETCODE_OK) {
    }
  }

 private:
  ipc::Payload payload_;
};

// FastDdsLoan: samples loaned from the writer's shared-memory pool; the reader
// reads them in place.
template <std::size_t N>
class Loans {
 public:
  explicit Loans(std::size_t) {}

  // Loans a sample, writes `seq` into it and writes it, waiting while the pool
  // or the writer's history is full.
  template <ipc::Side S>
  void send(S& side, dds::DataWriter& writer, std::uint64_t seq) {
    ipc::Patience<S> patience{side};
    Loan loan{writer};
    while (!loan.take()) patience.idle();
    ipc::stamp(loan.sample(), seq);
    while (!loan.write()) patience.idle();
  }

  // Takes the next sample in place, if there is one, checks it carries `seq`
  // (and that the writer did not reuse its memory while it was read), and
  // returns the loan.
  bool try_take(dds::DataReader& reader, std::uint64_t seq) {
    const auto code = reader.take(samples_, infos_, 1);
    if (code == ReturnCode::RETCODE_NO_DATA) return false;
    if (code != ReturnCode::RETCODE_OK) fail("take", code);
    const bool valid = infos_[0].valid_data;
    const std::uint64_t got = valid ? ipc::seq_of(samples_[0].data()) : 0;
    const bool intact = !valid || reader.is_sample_valid(&samples_[0], &infos_[0]);
    reader.return_loan(samples_, infos_);
    if (!valid) return false;  // news of a writer, not a message
    if (!intact) throw ipc::PeerError{"Fast DDS: the writer reused sample " + std::to_string(got) + " while it was read"};
    if (got != seq) throw ipc::out_of_sequence(seq, got);
    return true;
  }

  // Takes nothing: returning a loan while the writer's process is exiting
  // crashes inside Fast DDS 2.9 (DataReaderImpl::return_loan calls through a
  // null pointer once the writer's pool is gone: seen in about 1 run in 30).
  // The writer needs no drain to stop: its write() gives up after
  // max_blocking_time (100 ms) and it then sees the request to stop.
  void drain(dds::DataReader&) {}

 private:
  // A loaned sample; returned to the writer's pool unless it was written.
  class Loan {
   public:
    explicit Loan(dds::DataWriter& writer) : writer_{writer} {}
    Loan(const Loan&) = delete;
    Loan& operator=(const Loan&) = delete;
    ~Loan() {
      if (sample_ != nullptr) writer_.discard_loan(sample_);
    }

    // False while the pool is exhausted.
    bool take() {
      const auto code = writer_.loan_sample(sample_);
      if (code == ReturnCode::RETCODE_OUT_OF_RESOURCES) return false;
      if (code != ReturnCode::RETCODE_OK) fail("loan_sample", code);
      return true;
    }
    [[nodiscard]] void* sample() const noexcept { return sample_; }
    // False while the history is full (after max_blocking_time); the sample
    // stays loaned.
    bool write() {
      const auto code = writer_.write(sample_, dds::HANDLE_NIL);
      if (code == ReturnCode::RETCODE_TIMEOUT) return false;
      if (code != ReturnCode::RETCODE_OK) fail("write of a loan", code);
      sample_ = nullptr;
      return true;
    }

   private:
    dds::DataWriter& writer_;
    void* sample_ = nullptr;
  };

  dds::LoanableSequence<Sample<N>> samples_;
  dds::SampleInfoSeq infos_;
};

template <Mode kMode, std::size_t N>
using Messages = std::conditional_t<kMode == Mode::kShm, Copies, Loans<N>>;

constexpr const char* peer_name(Mode mode) { return mode == Mode::kShm ? "FastDdsShm" : "FastDdsLoan"; }
std::string entry(Mode mode, const char* role) { return std::string{peer_name(mode)} + "." + role; }

// ---- the child ---------------------------------------------------------------------

// arg(0): the topics' prefix, arg(1): the domain.
template <Mode kMode>
void echo(ipc::Child& self) {
  with_sample_size(self.bytes(), [&]<std::size_t N>() {
    Participant<N> node{kMode, Flow::kPingPong, std::stoi(self.arg(1))};
    auto& ping = node.reader(self.arg(0) + "_ping");
    auto& pong = node.writer(self.arg(0) + "_pong");
    Messages<kMode, N> messages{N};
    ipc::sleep_until(self, [&] { return matched(ping) && matched(pong); });
    self.ready();
    for (std::uint64_t seq = 1;; ++seq) {
      ipc::spin_until(self, [&] { return messages.try_take(ping, seq); });
      messages.send(self, pong, seq);
    }
  });
}
const ipc::ChildEntry kShmEcho{"FastDdsShm.echo", echo<Mode::kShm>};
const ipc::ChildEntry kLoanEcho{"FastDdsLoan.echo", echo<Mode::kLoan>};

template <Mode kMode>
void stream(ipc::Child& self) {
  with_sample_size(self.bytes(), [&]<std::size_t N>() {
    Participant<N> node{kMode, Flow::kStream, std::stoi(self.arg(1))};
    auto& out = node.writer(self.arg(0) + "_stream");
    Messages<kMode, N> messages{N};
    ipc::sleep_until(self, [&] { return matched(out); });
    self.ready();
    for (std::uint64_t seq = 1;; ++seq) {
      self.check();
      messages.send(self, out, seq);
    }
  });
}
const ipc::ChildEntry kShmStream{"FastDdsShm.stream", stream<Mode::kShm>};
const ipc::ChildEntry kLoanStream{"FastDdsLoan.stream", stream<Mode::kLoan>};

// ---- the parent ----------------------------------------------------------------------

// The parent's participant is made once the child is spawned (the Link pins
// this thread to its CPU, and Fast DDS's threads inherit that), but declared
// before the Link: the child is gone before it goes, and the Link's drain may
// use it until then.
template <Mode kMode>
void latency(benchmark::State& state) {
  ipc::run(state, [&](std::size_t bytes) {
    with_sample_size(bytes, [&]<std::size_t N>() {
      const Names names = new_names();
      std::optional<Participant<N>> node;
      ipc::Link child{entry(kMode, "echo"), N, {}, {names.topics, std::to_string(names.domain)}};
      node.emplace(kMode, Flow::kPingPong, names.domain);
      auto& ping = node->writer(names.topics + "_ping");
      auto& pong = node->reader(names.topics + "_pong");
      Messages<kMode, N> messages{N};
      child.wait_ready();
      ipc::sleep_until(child, [&] { return matched(ping) && matched(pong); });
      child.go();
      ipc::time_round_trips(state, [&](std::uint64_t seq) {
        messages.send(child, ping, seq);
        ipc::spin_until(child, [&] { return messages.try_take(pong, seq); });
      });
      child.stop();
    });
  });
}

template <Mode kMode>
void throughput(benchmark::State& state) {
  ipc::run(state, [&](std::size_t bytes) {
    with_sample_size(bytes, [&]<std::size_t N>() {
      const Names names = new_names();
      std::optional<Participant<N>> node;
      dds::DataReader* in = nullptr;
      Messages<kMode, N> messages{N};
      ipc::Link child{entry(kMode, "stream"), N, {}, {names.topics, std::to_string(names.domain)}};
      // The child may be waiting on a full history: keep taking until it is gone.
      child.set_drain([&] {
        if (in != nullptr) messages.drain(*in);
      });
      node.emplace(kMode, Flow::kStream, names.domain);
      in = &node->reader(names.topics + "_stream");
      child.wait_ready();
      ipc::sleep_until(child, [&] { return matched(*in); });
      child.go();
      ipc::time_stream(state, [&](std::uint64_t seq) {
        ipc::spin_until(child, [&] { return messages.try_take(*in, seq); });
      });
      child.stop();
    });
  });
}

void BM_Latency_FastDdsShm(benchmark::State& state) { latency<Mode::kShm>(state); }
void BM_Latency_FastDdsLoan(benchmark::State& state) { latency<Mode::kLoan>(state); }
void BM_Throughput_FastDdsShm(benchmark::State& state) { throughput<Mode::kShm>(state); }
void BM_Throughput_FastDdsLoan(benchmark::State& state) { throughput<Mode::kLoan>(state); }
BENCHMARK(BM_Latency_FastDdsShm)->Apply(ipc::latency_payloads);
BENCHMARK(BM_Latency_FastDdsLoan)->Apply(ipc::latency_payloads);
BENCHMARK(BM_Throughput_FastDdsShm)->Apply(ipc::throughput_payloads);
BENCHMARK(BM_Throughput_FastDdsLoan)->Apply(ipc::throughput_payloads);

}  // namespace
