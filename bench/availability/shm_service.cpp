// The Shm side of prime_availability: every party is a process of its own.
//
//   child  "Availability.shm_serve"   hosts "shout" (raw bytes in, 8-byte checksum
//                                     out), noting the main client's requests in a
//                                     Ledger the parent shares with it (a memfd)
//   parent                            the main client: posts every period
//                                     (availability) or calls and waits (response)
//   children "Availability.shm_extra" 0 or 5 extra clients, calling at random
//                                     intervals of 1..20 ms
#include <span>
#include <string>
#include <vector>

#include "availability.hpp"
#include "prime/shm.hpp"
#include "shm_domain.hpp"

namespace {

namespace av = prime::bench::availability;
namespace ipc = prime::bench::ipc;
namespace shm = prime::shm;
using namespace std::chrono_literals;

constexpr std::size_t kReplySize = sizeof(std::uint64_t);

shm::ClientQos client_qos() { return {.timeout = av::kCallTimeout, .wait_for_service = 10s}; }

// A call the service turned away (its queue, its clients or its rate were
// at their limits) or that timed out: counted as refused, not a failure.
bool refused(prime::Errc code) {
  using prime::Errc;
  return code == Errc::queue_full || code == Errc::too_many_clients || code == Errc::rate_limited ||
         code == Errc::timeout;
}

std::string_view as_text(std::span<const std::byte> bytes) {
  return {reinterpret_cast<const char*>(bytes.data()), bytes.size()};
}

std::span<const std::byte> as_bytes(const std::string& s) { return std::as_bytes(std::span{s.data(), s.size()}); }

// One synchronous call with `request`; the checksum it answered, or the error.
std::expected<std::uint64_t, prime::Error> call(const shm::ServiceChain<shm::Bytes, shm::Bytes>& service,
                                                const std::string& request) {
  std::uint64_t checksum = 0;
  auto done = service.call_in_place(
      [&](std::span<std::byte> to) {
        std::memcpy(to.data(), request.data(), request.size());
        return request.size();
      },
      [&](std::span<const std::byte> reply) {
        if (reply.size() == kReplySize) std::memcpy(&checksum, reply.data(), kReplySize);
      });
  if (!done) return std::unexpected(std::move(done.error()));
  return checksum;
}

// ---- the child processes ---------------------------------------------------

// arg(0): the domain; fd(0): the Ledger; bytes(): the text's length.
void serve(ipc::Child& self) {
  auto mapping = ipc::SharedMapping::adopt(self.fd(0), sizeof(av::Ledger));
  auto& ledger = mapping.as<av::Ledger>();
  shm::Core core{self.arg(0)};
  (void)core.serve_in_place<shm::Bytes, shm::Bytes>(
      "shout",
      [&ledger](std::span<const std::byte> request, std::span<std::byte> reply) {
        const std::uint64_t checksum = av::serve_request(ledger, as_text(request));
        std::memcpy(reply.data(), &checksum, kReplySize);
        return kReplySize;
      },
      {.timeout = av::kCallTimeout, .max_request_size = av::kHeaderSize + self.bytes(), .max_reply_size = kReplySize});
  self.ready();
  ipc::sleep_until(self, [] { return false; });  // its worker serves until the parent stops it
}
const ipc::ChildEntry kServe{"Availability.shm_serve", serve};

// arg(0): the domain; bytes(): the text's length.
void extra_client(ipc::Child& self) {
  shm::Core core{self.arg(0)};
  auto service = core.chain<shm::Bytes, shm::Bytes>("shout", client_qos());
  auto request = av::make_request({.from = av::Header::kExtra}, self.bytes());
  av::call_at_random_intervals(self, [&](std::uint64_t seq) {
    av::set_header(request, {.from = av::Header::kExtra, .seq = seq, .sent_ns = av::now_ns()});
    auto got = call(service, request);
    if (!got && !refused(got.error().code))
      throw ipc::PeerError{"extra client: " + got.error().describe()};
  });
}
const ipc::ChildEntry kExtra{"Availability.shm_extra", extra_client};

// ---- the parent: server, extra clients, and the main client ---------------

// The processes of one configuration, started and ready; stopped (extra
// clients first) when it goes.
class Setup {
 public:
  Setup(std::size_t chars, std::size_t extra_clients)
      : domain_{ipc::new_shm_domain()},
        core_{domain_},
        mapping_{ipc::SharedMapping::create("prime-availability-ledger", sizeof(av::Ledger))},
        ledger_{mapping_.construct<av::Ledger>()} {
    server_.emplace("Availability.shm_serve", chars, std::vector<int>{mapping_.fd()}, std::vector<std::string>{domain_});
    server_->wait_ready();
    server_->go();
    av::start_extra_clients(extras_.emplace(), "Availability.shm_extra", extra_clients, chars,
                            std::vector<std::string>{domain_});
  }
  Setup(const Setup&) = delete;
  Setup& operator=(const Setup&) = delete;
  ~Setup() {
    extras_.reset();
    server_.reset();
  }

  shm::Core& core() { return core_; }
  av::Ledger& ledger() { return ledger_; }

  // Throws PeerError if any process has died or failed.
  void check() {
    server_->check();
    extras_->check();
  }

  // Stops every process, reporting a failure of any.
  void stop() {
    extras_->stop();
    server_->stop();
  }

 private:
  std::string domain_;
  shm::Core core_;
  ipc::SharedMapping mapping_;
  av::Ledger& ledger_;
  std::optional<ipc::Link> server_;
  std::optional<ipc::Links> extras_;
};

void BM_Availability_Shm(benchmark::State& state) {
  av::run_once(state, [&] {
    const std::chrono::milliseconds period{state.range(0)};
    const auto chars = static_cast<std::size_t>(state.range(1));
    Setup setup{chars, static_cast<std::size_t>(state.range(2))};
    auto service = setup.core().chain<shm::Bytes, shm::Bytes>("shout", client_qos());
    // One call first, untimed and not counted: the client binds to the service.
    auto request = av::make_request({.from = av::Header::kExtra}, chars);
    if (auto first = call(service, request); !first) throw ipc::PeerError{"shm service: " + first.error().describe()};
    av::clear(setup.ledger());

    const auto n = av::requests_for(period);
    auto sending = av::send_periodically(
        n, period,
        [&](std::size_t seq, std::int64_t sent_ns) {
          av::set_header(request, {.from = av::Header::kMain, .seq = seq, .sent_ns = sent_ns});
          auto posted = service.post(as_bytes(request));
          if (posted) return std::optional<std::string>{};
          const auto code = posted.error().code;
          if (refused(code))
            return std::optional<std::string>{posted.error().describe()};  // refused
          throw ipc::PeerError{"shm service: " + posted.error().describe()};
        },
        [&] { setup.check(); });
    // What is queued still runs: wait for it, a bounded time.
    const auto give_up = av::SteadyClock::now() + av::kDrainTime;
    while (av::executed(setup.ledger(), sending.sent) + sending.refused < sending.sent &&
           av::SteadyClock::now() < give_up) {
      setup.check();
      std::this_thread::sleep_for(1ms);
    }
    av::report_availability(state, sending, setup.ledger(), period);
    setup.stop();
  });
}
BENCHMARK(BM_Availability_Shm)->Apply(av::availability_configurations);

void BM_Response_Shm(benchmark::State& state) {
  av::run_once(state, [&] {
    const auto chars = static_cast<std::size_t>(state.range(0));
    Setup setup{chars, static_cast<std::size_t>(state.range(1))};
    auto service = setup.core().chain<shm::Bytes, shm::Bytes>("shout", client_qos());
    auto request = av::make_request({}, chars);
    const auto expected = av::shout(av::text_of(request));
    std::size_t checked = 0;
    av::time_calls(state, av::kShmResponseCalls, [&](std::uint64_t seq) {
      av::set_header(request, {.from = av::Header::kMain, .seq = av::kMaxRequests + seq, .sent_ns = av::now_ns()});
      auto got = call(service, request);
      if (!got) {
        setup.check();
        throw ipc::PeerError{"shm service: " + got.error().describe()};
      }
      if (*got != expected) throw ipc::PeerError{"shm service: a wrong checksum"};
      if (++checked % 64 == 0) setup.check();
    });
    setup.stop();
  });
}
BENCHMARK(BM_Response_Shm)->Apply(av::response_configurations);

}  // namespace
