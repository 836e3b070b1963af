// Shm services within one process: serving and calling, in place both ways,
// the errors and limits a caller meets, linked services that forward, and
// the cost of an idle service. Across processes: service_process_test.cpp.
#include <gtest/gtest.h>
#include <sys/resource.h>

#include <atomic>
#include <chrono>
#include <cstdint>
#include <expected>
#include <fstream>
#include <future>
#include <latch>
#include <new>
#include <optional>
#include <stop_token>
#include <string>
#include <thread>
#include <vector>

#include "prime/liberty.hpp"
#include "prime/shm.hpp"
#include "prime/shm/detail/segment.hpp"
#include "prime/shm/detail/service_layout.hpp"
#include "shm/domain.hpp"
#include "shm/mappings.hpp"
#include "shm/mapped_topic.hpp"
#include "support/failure.hpp"
#include "support/threads.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

struct Pose {
  double x, y;
};
struct Path {
  std::uint32_t steps;
  double length;
};

Path plan(const Pose& p) { return {static_cast<std::uint32_t>(p.x + p.y), p.x * 2}; }

std::optional<shm::RegistrySnapshot::Service> listed(shm::Core& core, const std::string& name) {
  for (const auto& s : core.registry().services)
    if (s.name == name) return s;
  return std::nullopt;
}

class ServiceTest : public ::testing::Test {
 protected:
  shm::Core core{unique_domain("service"), {.participant = "server"}};
};

// A service's segment as a foreign or broken program maps it: found by its
// header as it is now.
class MappedService {
 public:
  MappedService(const std::string& domain, const std::string& name)
      : segment_{shm::detail::Segment::open_existing(shm::detail::segment_name(domain, "service", name))} {
    if (!segment_) throw std::runtime_error{"no service '" + name + "' in domain '" + domain + "'"};
  }
  [[nodiscard]] shm::detail::ServiceHeader& header() const {
    return *std::launder(reinterpret_cast<shm::detail::ServiceHeader*>(segment_->data()));
  }
  [[nodiscard]] shm::detail::CellHeader& cell(std::size_t i) const {
    return *std::launder(reinterpret_cast<shm::detail::CellHeader*>(at(i)));
  }
  [[nodiscard]] shm::detail::CellTail& tail(std::size_t i) const {
    return *std::launder(reinterpret_cast<shm::detail::CellTail*>(at(i) + header().tail_offset));
  }
  [[nodiscard]] std::byte* reply(std::size_t i) const { return at(i) + header().reply_offset; }

  // Queues cell `i` as a caller would, with what `write` puts in it; the
  // state the call ends in (within 10 s; queued or running if it does not).
  template <class Write>
  shm::detail::CellState call(std::size_t i, Write write) const {
    using shm::detail::CellState;
    using shm::detail::Status;
    auto& c = cell(i);
    const auto ticket = Status::ticket(c.status.load());
    c.posted = 0;
    c.next_hops = 0;
    write(c, tail(i));
    c.status.store(Status::pack(ticket, CellState::queued));
    header().pending[i / 64].fetch_or(1ull << (i % 64));
    header().requests.ring_always();
    auto ended = [&] {
      const auto state = Status::state(c.status.load());
      return state != CellState::queued && state != CellState::running;
    };
    if (!MappedTopic::within(10s, ended)) return Status::state(c.status.load());
    const auto state = Status::state(c.status.load());
    c.status.store(Status::pack(ticket + 1, CellState::free));  // as its caller frees it
    return state;
  }

 private:
  [[nodiscard]] std::byte* at(std::size_t i) const {
    return segment_->data() + header().cells_offset + i * header().cell_stride;
  }
  std::optional<shm::detail::Segment> segment_;
};


TEST_F(ServiceTest, ADamagedServiceFailsItsCallsByNameAndToolsPassItOver) {
  core.serve("echo", [](const Pose& p) { return p; });
  {
    shm::Core server{core.domain(), {.participant = "planner"}};
    server.serve("planner", plan);
  }  // stopped: the damage below is not under a running server's feet
  {
    auto segment = shm::detail::Segment::open_existing(shm::detail::segment_name(core.domain(), "service", "planner"));
    ASSERT_TRUE(segment);
    std::launder(reinterpret_cast<shm::detail::ServiceHeader*>(segment->data()))->cell_count = 1000;
  }
  shm::Core client{core.domain(), {.participant = "client"}};
  auto planner = client.chain<Pose, Path>("planner");
  const auto value = planner.call({1, 1});
  ASSERT_FALSE(value);
  EXPECT_EQ(value.error().code, Errc::damaged);
  EXPECT_NE(value.error().message.find("service 'planner': its shared memory is damaged (1000 cells"), std::string::npos)
      << value.error().describe();
  EXPECT_FALSE(listed(client, "planner"));
  EXPECT_TRUE(listed(client, "echo"));
  auto echo = client.chain<Pose, Pose>("echo");
  EXPECT_EQ(echo(Pose{2, 3}).y, 3.0);
}

TEST_F(ServiceTest, AServedBlockIsCalledLikeAnyChainAndListedInTheRegistry) {
  core.serve("planner", plan, {.workers = 2});
  shm::Core client{core.domain(), {.participant = "client"}};
  auto planner = client.chain<Pose, Path>("planner");
  const auto path = planner({3, 4});
  EXPECT_EQ(path.steps, 7u);
  EXPECT_EQ(path.length, 6.0);
  auto value = planner.call({1, 1});
  ASSERT_TRUE(value) << value.error().describe();
  EXPECT_EQ(value->steps, 2u);

  const auto seen = listed(core, "planner");
  ASSERT_TRUE(seen);
  EXPECT_NE(seen->request_type.find("Pose (16 bytes"), std::string::npos) << seen->request_type;
  EXPECT_NE(seen->reply_type.find("Path (16 bytes"), std::string::npos) << seen->reply_type;
  EXPECT_EQ(seen->server, "server");
  EXPECT_EQ(seen->server_pid, static_cast<std::uint32_t>(::getpid()));
  EXPECT_EQ(seen->client_pids, std::vector<std::uint32_t>{static_cast<std::uint32_t>(::getpid())});
  EXPECT_EQ(seen->served, 2u);
  EXPECT_EQ(seen->qos.workers, 2u);
}

TEST_F(ServiceTest, ARequestIsReadInPlaceWhereTheCallerWroteIt) {
  std::atomic<const void*> request_at{nullptr};
  shm::Core core{unique_domain("in-place")};  // stopped before what its block uses goes
  core.serve("in-place", [&](const Pose& p) {
    request_at = &p;
    return plan(p);
  });
  auto service = core.chain<Pose, Path>("in-place");
  ASSERT_TRUE(service.call({1, 2}));
  EXPECT_TRUE(inside_mapping_of("service.in-place", request_at.load())) << "the block read the request in shared memory";
}

TEST_F(ServiceTest, AnExceptionComesBackWithItsMessageAndTheServiceServesOn) {
  core.serve("picky", [](const Pose& p) {
    if (p.x < 0) throw std::domain_error{"no negative x"};
    return plan(p);
  });
  auto picky = core.chain<Pose, Path>("picky");
  auto failed = picky.call({-1, 0});
  ASSERT_FALSE(failed);
  EXPECT_EQ(failed.error().code, Errc::block_failed);
  EXPECT_EQ(failed.error().message, "service 'picky': no negative x");
  EXPECT_TRUE(fails_with([&] { (void)picky({-2, 0}); }, Errc::block_failed, "no negative x")) << "operator() throws it";
  EXPECT_EQ(picky({1, 0}).steps, 1u) << "the service serves on";
  EXPECT_EQ(listed(core, "picky")->failed, 2u);
}

TEST_F(ServiceTest, NoServiceFailsAtOnceUnlessTheCallerWaitsForOne) {
  auto nobody = core.chain<Pose, Path>("nobody", {.timeout = 10s});
  const auto t0 = Clock::now();
  auto none = nobody.call({1, 1});
  ASSERT_FALSE(none);
  EXPECT_EQ(none.error().code, Errc::not_found);
  EXPECT_NE(none.error().message.find("no service 'nobody'"), std::string::npos) << none.error().message;
  EXPECT_LT(Clock::now() - t0, 5s) << "at once, not after the 10 s timeout";

  auto patient = core.chain<Pose, Path>("later", {.wait_for_service = 20s});
  std::jthread starter{[&, waiting = ::gettid()] {
    if (asleep_within(waiting)) core.serve("later", plan);  // once the call below waits for it
  }};
  auto late = patient.call({2, 2});
  ASSERT_TRUE(late) << late.error().describe();
  EXPECT_EQ(late->steps, 4u);
}

TEST_F(ServiceTest, CallingWithOtherTypesNamesTheServiceAndBothTypes) {
  core.serve("planner", plan);
  auto wrong = core.chain<int, Path>("planner").call(1);
  ASSERT_FALSE(wrong);
  EXPECT_EQ(wrong.error().code, Errc::type_mismatch);
  EXPECT_NE(wrong.error().message.find("service 'planner' takes prime::test::{anonymous}::Pose"), std::string::npos)
      << wrong.error().message;
  EXPECT_NE(wrong.error().message.find("not int (4 bytes"), std::string::npos) << wrong.error().message;
  EXPECT_TRUE(fails_with([&] { core.serve("planner", plan); }, Errc::in_use, "service 'planner' is served already"));
}

// Counts a latch down once: now(), or at the latest when it goes. Declared
// after the core whose block waits on the latch, it lets that block finish
// before the core's stop waits for it, even when a test ends early.
struct ReleaseOnce {
  std::latch& latch;
  bool done = false;
  void now() {
    if (!std::exchange(done, true)) latch.count_down();
  }
  ~ReleaseOnce() { now(); }
};

TEST_F(ServiceTest, AnAnswerAfterItsCallTimedOutNeverReachesALaterCall) {
  std::latch release{1};
  std::atomic<bool> entered{false};
  shm::Core core{unique_domain("slow")};  // stopped before what its block uses goes
  ReleaseOnce release_guard{release};
  core.serve("slow", [&](const int& x) {
    if (x == 1) {
      entered = true;
      release.wait();
    }
    return x * 10;
  });
  auto slow = core.chain<int, int>("slow", {.timeout = 100ms});
  auto timed_out = slow.call(1);
  ASSERT_FALSE(timed_out);
  EXPECT_EQ(timed_out.error().code, Errc::timeout);
  EXPECT_NE(timed_out.error().message.find("service 'slow'"), std::string::npos);
  EXPECT_TRUE(entered);
  release_guard.now();  // the worker answers call 1 now, for no one
  for (int i = 2; i < 200; ++i) {
    auto got = slow.call(i);
    ASSERT_TRUE(got) << got.error().describe();
    ASSERT_EQ(*got, i * 10) << "each call gets its own answer";
  }
}

// A caller that must stop waiting (a shutdown, Ctrl-C in Python) gives its
// call up well before the call's timeout; the answer it left is dropped.
TEST_F(ServiceTest, ACallGivenUpEndsStoppedBeforeItsTimeoutAndItsAnswerReachesNoLaterCall) {
  std::latch release{1};
  std::atomic<bool> entered{false};
  shm::Core core{unique_domain("given-up")};  // stopped before what its block uses goes
  ReleaseOnce release_guard{release};
  core.serve("held", [&](const int& x) {
    if (x == 1) {
      entered = true;
      entered.notify_all();
      release.wait();
    }
    return x * 10;
  }, {.workers = 2});
  auto held = core.chain<int, int>("held", {.timeout = 60s});
  std::stop_source stop;
  std::atomic<int> asked{0};
  std::promise<std::expected<int, Error>> given_up;
  std::jthread caller{[&] {
    given_up.set_value(held.call(1, [&] {
      ++asked;
      return stop.stop_requested();
    }));
  }};
  entered.wait(false);  // the request is in a worker: the caller waits for its answer
  stop.request_stop();
  auto result = given_up.get_future();
  ASSERT_EQ(result.wait_for(10s), std::future_status::ready) << "a given-up call waited on";
  auto got = result.get();
  ASSERT_FALSE(got);
  EXPECT_EQ(got.error().code, Errc::stopped);
  EXPECT_NE(got.error().message.find("service 'held': the caller gave this call up"), std::string::npos)
      << got.error().message;
  EXPECT_GE(asked.load(), 1);
  release_guard.now();  // the worker answers call 1 now, for no one
  for (int i = 2; i < 50; ++i) {
    auto next = held.call(i, [] { return false; });
    ASSERT_TRUE(next) << next.error().describe();
    ASSERT_EQ(*next, i * 10) << "each call gets its own answer";
  }
}

// A service's geometry (its cells' stride and offsets, its counts and
// sizes) is read once, when its header is checked: a write there
// afterwards (a foreign or broken program) sends neither server nor client
// out of the segment, and calls go on.
TEST_F(ServiceTest, AServiceHeaderWrittenAfterItWasCheckedSendsNoAccessOutOfTheSegment) {
  core.serve("planner", plan, {.max_clients = 2});
  core.serve("twice", [](std::span<const std::byte> b) {
    std::vector<std::byte> out(b.begin(), b.end());
    out.insert(out.end(), b.begin(), b.end());
    return out;
  }, {.max_request_size = 100, .max_reply_size = 100});
  auto planner = core.chain<Pose, Path>("planner");
  auto second = core.chain<Pose, Path>("planner");
  auto twice = core.chain<shm::Bytes, shm::Bytes>("twice");
  ASSERT_EQ(planner(Pose{1, 2}).steps, 3u);  // client slot 0
  ASSERT_EQ(second(Pose{2, 2}).steps, 4u);   // client slot 1
  const std::vector<std::byte> ten(10, std::byte{1}), sixty(60, std::byte{2});
  ASSERT_EQ(twice(ten).size(), 20u);
  for (const auto* name : {"planner", "twice"}) {
    const MappedService mapped{core.domain(), name};
    auto& h = mapped.header();
    constexpr std::uint64_t kFar = 1ull << 40;
    h.cell_stride = h.request_offset = h.reply_offset = h.tail_offset = h.cells_offset = kFar;
    h.max_request_size = h.max_reply_size = kFar;
    h.max_clients = h.calls_per_client = h.cell_count = 1000;
  }
  for (int i = 0; i < 20; ++i) {
    for (auto* client : {&planner, &second}) {
      const auto path = client->call(Pose{static_cast<double>(i), 1});
      ASSERT_TRUE(path) << path.error().describe();
      EXPECT_EQ(path->steps, static_cast<std::uint32_t>(i + 1));
      EXPECT_EQ(path->length, 2.0 * i);
    }
    ASSERT_EQ(twice(ten).size(), 20u);
  }
  const auto too_big = twice.call(std::vector<std::byte>(101, std::byte{3}));
  ASSERT_FALSE(too_big) << "101 bytes do not fit the service's requests as it was made";
  EXPECT_NE(too_big.error().message.find("a request of 101 bytes exceeds max_request_size (100 bytes)"), std::string::npos)
      << too_big.error().describe();
  const auto too_long = twice.call(sixty);
  ASSERT_FALSE(too_long) << "120 bytes do not fit the service's replies as it was made";
  EXPECT_NE(too_long.error().message.find("a reply of 120 bytes exceeds the 100 bytes it may take (this service's max_reply_size"), std::string::npos)
      << too_long.error().describe();

  // A participant that maps it afresh finds the damage, and says so.
  shm::Core other{core.domain(), {.participant = "client"}};
  const auto refused = other.chain<Pose, Path>("planner").call(Pose{1, 1});
  ASSERT_FALSE(refused);
  EXPECT_NE(refused.error().message.find("service 'planner': its shared memory is damaged (1000 client slots"),
            std::string::npos)
      << refused.error().describe();
}

// A call a foreign or broken caller queued with sizes, a route or a cell
// out of range fails alone, by name, or goes unanswered; the worker reads
// nothing out of the service's segment, and other calls go on.
TEST_F(ServiceTest, ACallDamagedInSharedMemoryFailsAloneAndTheServiceGoesOn) {
  using shm::detail::CellState;
  std::atomic<std::size_t> seen{0};
  core.serve("sizes", [&](std::span<const std::byte> b) {
    seen = b.size();
    return std::vector<std::byte>(b.begin(), b.end());
  }, {.max_request_size = 100, .max_reply_size = 100, .max_clients = 2});
  core.serve("echo", [](std::span<const std::byte> b) { return std::vector<std::byte>(b.begin(), b.end()); },
             {.max_request_size = 100, .max_reply_size = 100, .max_clients = 2});
  auto linked = core.chain<shm::Bytes, shm::Bytes>("sizes") | core.chain<shm::Bytes, shm::Bytes>("echo");
  const std::vector<std::byte> ten(10, std::byte{3});
  ASSERT_EQ(linked(ten), ten);  // client slot 0 of each: cell 0
  const MappedService sizes{core.domain(), "sizes"};
  const auto echo_index = sizes.tail(0).next[0].service;  // where the linked call went on

  EXPECT_EQ(sizes.call(1, [](auto& c, auto&) { c.request_size = 1ull << 40; }), CellState::done);
  EXPECT_EQ(seen, 100u) << "a request's size past max_request_size ends there";
  EXPECT_EQ(sizes.cell(1).reply_size, 100u);

  EXPECT_EQ(sizes.call(1, [](auto& c, auto&) {
    c.request_size = 10;
    c.next_hops = 100;
  }), CellState::failed);
  EXPECT_NE(std::string{sizes.tail(1).error}.find("service 'sizes': a call's cell is damaged (100 services after this "
                                                  "one, at most 7)"),
            std::string::npos)
      << sizes.tail(1).error;

  seen = 0;
  EXPECT_EQ(sizes.call(1, [&](auto& c, auto& tail) {
    c.request_size = 10;
    c.next_hops = 1;
    tail.next[0] = {echo_index, 9999, 0};  // a cell echo does not have
  }), CellState::done) << "as a call whose caller gave up: no answer";
  EXPECT_EQ(seen, 0u) << "not run: its output had nowhere to go";

  // A pending bit for a cell past the service's: cleared, and nothing runs.
  sizes.header().pending[3].fetch_or(1ull << 63);
  sizes.header().requests.ring_always();
  EXPECT_TRUE(MappedTopic::within(10s, [&] { return sizes.header().pending[3].load() == 0; }));
  for (int i = 0; i < 10; ++i) ASSERT_EQ(linked(ten), ten);
}

TEST_F(ServiceTest, LimitsAreErrorsThatNameTheLimitAndTheService) {
  core.serve("bytes", [](std::span<const std::byte> b) { return std::vector<std::byte>(b.begin(), b.end()); },
             {.max_request_size = 100, .max_reply_size = 100, .max_clients = 2});
  auto bytes = core.chain<shm::Bytes, shm::Bytes>("bytes");
  const std::vector<std::byte> hundred(100, std::byte{7}), more(101, std::byte{7});
  EXPECT_EQ(bytes(hundred), hundred);
  auto oversized = bytes.call(more);
  ASSERT_FALSE(oversized);
  EXPECT_EQ(oversized.error().code, Errc::too_large);
  EXPECT_NE(oversized.error().message.find("exceeds max_request_size (100 bytes)"), std::string::npos)
      << oversized.error().message;

  auto second = core.chain<shm::Bytes, shm::Bytes>("bytes");
  ASSERT_TRUE(second.call(hundred));
  auto third = core.chain<shm::Bytes, shm::Bytes>("bytes").call(hundred);
  ASSERT_FALSE(third);
  EXPECT_EQ(third.error().code, Errc::too_many_clients);
  EXPECT_NE(third.error().message.find("service 'bytes' has its maximum of 2 clients (max_clients)"), std::string::npos)
      << third.error().message;

  core.serve("rate", [](const int& x) { return x; }, {.min_interval = 10s});
  auto rate = core.chain<int, int>("rate");
  ASSERT_TRUE(rate.call(1));
  auto soon = rate.call(2);
  ASSERT_FALSE(soon);
  EXPECT_EQ(soon.error().code, Errc::rate_limited);
  EXPECT_NE(soon.error().message.find("service 'rate': a client sends at most one request every 10000000 us (min_interval)"),
            std::string::npos)
      << soon.error().message;
}

TEST_F(ServiceTest, AFullQueueAndTooManyCallsInFlightAreRefusedByName) {
  std::latch release{1};
  std::atomic<int> running{0};
  // A core of this test's own, made after what its block uses and so
  // stopped (its worker joined) before that goes.
  shm::Core core{unique_domain("busy")};
  struct Release {  // the worker goes on even if an assertion ends the test early
    std::latch& latch;
    ~Release() { latch.count_down(); }
  } release_at_end{release};
  core.serve("busy", [&](const int& x) {
    ++running;
    release.wait();
    return x;
  }, {.calls_per_client = 2, .queue_depth = 2});
  auto first = core.chain<int, int>("busy");
  ASSERT_TRUE(first.post(1));
  ASSERT_TRUE(MappedTopic::within(10s, [&] { return running == 1; })) << "the worker runs the first";
  ASSERT_TRUE(first.post(2)) << "the second waits in the queue";
  auto third = first.post(3);
  ASSERT_FALSE(third);
  EXPECT_EQ(third.error().code, Errc::queue_full);
  EXPECT_NE(third.error().message.find("service 'busy': this client has 2 calls in flight already (calls_per_client)"),
            std::string::npos)
      << third.error().message;
  auto other = core.chain<int, int>("busy");
  ASSERT_TRUE(other.post(4)) << "another client's waits in the queue too";
  auto full = other.post(5);
  ASSERT_FALSE(full);
  EXPECT_EQ(full.error().code, Errc::queue_full);
  EXPECT_NE(full.error().message.find("service 'busy': 2 requests wait for a worker already (queue_depth)"),
            std::string::npos)
      << full.error().message;
}

TEST_F(ServiceTest, PostSendsWithoutWaitingForTheAnswer) {
  std::atomic<int> sum{0};
  shm::Core core{unique_domain("sink")};  // stopped before what its block uses goes
  core.serve("sink", [&](const int& x) {
    sum += x;
    return 0;
  });
  auto sink = core.chain<int, int>("sink");
  for (int i = 1; i <= 100; ++i) {
    while (true) {  // four in flight at most: a post refused for that is sent again
      auto sent = sink.post(i);
      if (sent) break;
      ASSERT_NE(sent.error().message.find("calls_per_client"), std::string::npos) << sent.error().describe();
    }
  }
  EXPECT_TRUE(MappedTopic::within(10s, [&] { return sum == 5050; }));
}

// A post is sent when post() returns: the handle that sent it may go at
// once, the post is still run (and so is the rest of its linked route).
TEST_F(ServiceTest, APostOutlivesTheHandleThatSentIt) {
  std::latch may_go{1};
  std::atomic<int> got{0};
  core.serve("busy", [&](const int& x) {
    if (x < 0) may_go.wait();  // one worker: a post sent meanwhile waits in the queue
    return x;
  });
  core.serve("sink", [&](const int& x) {
    got = x;
    return 0;
  });
  std::jthread blocker{[busy = core.chain<int, int>("busy")] { EXPECT_EQ(busy(-1), -1); }};
  ASSERT_TRUE(MappedTopic::within(10s, [&] { return listed(core, "busy")->requests_from_callers == 1; }));
  ASSERT_TRUE((core.chain<int, int>("busy") | core.chain<int, int>("sink")).post(7));  // its handle goes at once
  may_go.count_down();
  EXPECT_TRUE(MappedTopic::within(10s, [&] { return got == 7; })) << "the post reached the end of its route";
}

TEST_F(ServiceTest, LinkedServicesForwardSoTheCallerSendsOnceAndWaitsOnce) {
  core.serve("double", [](const int& x) { return 2 * x; });
  core.serve("describe", [](const int& x) { return bounded_string<16>{std::to_string(x)}; });
  auto doubled = core.chain<int, int>("double");
  auto described = core.chain<int, bounded_string<16>>("describe");
  auto linked = doubled | described;
  static_assert(std::same_as<decltype(linked), shm::ServiceChain<int, bounded_string<16>>>);
  for (int i = 0; i < 100; ++i) ASSERT_EQ(linked(i), std::to_string(2 * i));
  auto a = *listed(core, "double");
  auto b = *listed(core, "describe");
  EXPECT_EQ(a.requests_from_callers, 100u);
  EXPECT_EQ(a.replies_to_callers, 0u) << "no answer went back to the caller from the first";
  EXPECT_EQ(a.outputs_forwarded_on, 100u);
  EXPECT_EQ(b.requests_from_callers, 0u) << "the caller never sent to the second";
  EXPECT_EQ(b.requests_forwarded_in, 100u);
  EXPECT_EQ(b.replies_to_callers, 100u);

  for (int i = 0; i < 100; ++i) ASSERT_EQ(described(doubled(i)), std::to_string(2 * i));  // routed by the caller
  EXPECT_EQ(listed(core, "double")->replies_to_callers, 100u);
  EXPECT_EQ(listed(core, "describe")->requests_from_callers, 100u);
  EXPECT_EQ(linked.graph().text(), "double [service, shm] -> describe [service, shm]\n");
}

TEST_F(ServiceTest, AFailureInsideALinkedCallReachesTheCaller) {
  core.serve("check", [](const int& x) {
    if (x < 0) throw std::invalid_argument{"negative"};
    return x;
  });
  core.serve("plus", [](const int& x) { return x + 1; });
  auto linked = core.chain<int, int>("check") | core.chain<int, int>("plus");
  auto failed = linked.call(-5);
  ASSERT_FALSE(failed);
  EXPECT_EQ(failed.error().code, Errc::block_failed);
  EXPECT_EQ(failed.error().message, "service 'check': negative");
  EXPECT_EQ(linked(5), 6);
}

// A post down a linked route marks its cells of the later services as
// posted (their workers free them); the calls that take those cells next
// are calls like any other: answered, or told why they failed.
TEST_F(ServiceTest, CallsAfterAPostDownALinkedRouteAreAnsweredOrToldWhy) {
  std::atomic<int> posts_done{0};
  core.serve("gate", [](const int& x) {
    if (x < 0) throw std::invalid_argument{"negative"};
    return x;
  });
  core.serve("count", [&](const int& x) {
    if (x >= 1000) ++posts_done;
    return x + 1;
  });
  auto linked = core.chain<int, int>("gate") | core.chain<int, int>("count");
  for (int i = 0; i < 4; ++i) ASSERT_TRUE(linked.post(1000 + i));  // every cell of this client, as calls_per_client is 4
  ASSERT_TRUE(MappedTopic::within(10s, [&] { return posts_done == 4; }));
  // A post's cells are free once its worker is done: a call before then is
  // refused as one too many in flight, and sent again.
  auto call = [&](int x) {
    while (true) {
      auto out = linked.call(x);
      if (out || out.error().message.find("calls_per_client") == std::string::npos) return out;
    }
  };
  for (int i = 0; i < 8; ++i) {
    auto failed = call(-1);
    ASSERT_FALSE(failed);
    EXPECT_EQ(failed.error().code, Errc::block_failed) << i << ": " << failed.error().describe();
    auto answered = call(i);
    ASSERT_TRUE(answered) << i << ": " << answered.error().describe();
    EXPECT_EQ(*answered, i + 1);
  }
}

// A post whose first service fails frees every later cell of its route:
// its caller waits for no answer and releases nothing, so a cell left
// claimed would cost that client a call in flight at that service for good.
TEST_F(ServiceTest, APostThatFailsDownALinkedRouteFreesEveryCellOfIt) {
  core.serve("gate", [](const int& x) {
    if (x < 0) throw std::invalid_argument{"negative"};
    return x;
  });
  for (const auto* name : {"a", "b", "c"}) core.serve(name, [](const int& x) { return x + 1; }, {.calls_per_client = 1});
  auto a = core.chain<int, int>("a");
  auto b = core.chain<int, int>("b");
  auto c = core.chain<int, int>("c");
  auto linked = core.chain<int, int>("gate") | a | b | c;
  ASSERT_TRUE(linked.post(-1));
  ASSERT_TRUE(MappedTopic::within(10s, [&] { return listed(core, "gate")->failed == 1; }));
  for (auto* one : {&a, &b, &c}) {  // one call in flight each: refused for as long as the post holds its cell
    std::expected<int, Error> out = std::unexpected(Error{});
    EXPECT_TRUE(MappedTopic::within(10s, [&] { return (out = one->call(1)).has_value(); })) << out.error().describe();
  }
  EXPECT_EQ(linked(1), 4);
}

// A linked call holds a cell of each later service's segment. When one
// comes back with other limits (a new segment under the same name) before
// the call reaches it, the cell it held went with the old segment: its
// output must never land in the cell with the same place and ticket in the
// new one, which another call holds.
TEST_F(ServiceTest, AnOutputForAServiceMadeAnewNeverLandsInAnotherCallsCell) {
  std::latch first_may_go{1}, other_may_go{1};
  auto blocking = [](std::latch& gate) {
    return [&gate](const int& x) {
      if (x < 0) gate.wait();  // one worker each: what comes next waits in the queue
      return x;
    };
  };
  core.serve("first", blocking(first_may_go));
  core.serve("other_first", blocking(other_may_go));
  auto all_free = [&](const std::string& name) {
    MappedService mapped{core.domain(), name};
    for (std::size_t i = 0; i < mapped.header().cell_count; ++i)
      if (shm::detail::Status::state(mapped.cell(i).status.load()) != shm::detail::CellState::free) return false;
    return true;
  };
  auto blocker = [&](const std::string& name) {
    return std::jthread{[&, chain = core.chain<int, int>(name)] { EXPECT_EQ(chain(-1), -1); }};
  };
  auto first_blocked = blocker("first");
  ASSERT_TRUE(MappedTopic::within(10s, [&] { return listed(core, "first")->requests_from_callers == 1; }));
  auto posting = core.chain<int, int>("first") | core.chain<int, int>("add");
  {
    shm::Core old_server{core.domain()};
    old_server.serve("add", [](const int& x) { return x + 100; });
    ASSERT_TRUE(posting.post(1)) << "queued behind the blocker";
  }  // its server stops; the next one asks for other limits
  shm::Core new_server{core.domain()};
  new_server.serve("add", [](const int& x) { return x + 200; }, {.max_clients = 8});
  auto other_blocked = blocker("other_first");
  ASSERT_TRUE(MappedTopic::within(10s, [&] { return listed(core, "other_first")->requests_from_callers == 1; }));
  std::optional<std::expected<int, Error>> answer;
  std::jthread call{[&, linked = core.chain<int, int>("other_first") | core.chain<int, int>("add")] {
    answer = linked.call(5);  // its cell in the new segment is claimed, waiting for other_first's output
  }};
  ASSERT_TRUE(MappedTopic::within(10s, [&] { return listed(core, "other_first")->requests_from_callers == 2; }));
  first_may_go.count_down();  // the post goes on, towards a segment that is gone
  first_blocked.join();
  ASSERT_TRUE(MappedTopic::within(10s, [&] { return all_free("first"); })) << "the post is done with";
  other_may_go.count_down();
  call.join();
  ASSERT_TRUE(answer && *answer) << (answer ? answer->error().describe() : "no answer");
  EXPECT_EQ(**answer, 205) << "its own request's answer, never the post's";
}

// No caller frees a post's cells: when its route cannot go on (the next
// service was made anew), the cells it held further on are freed all the same.
TEST_F(ServiceTest, APostThatCannotGoOnFreesTheRestOfItsRoute) {
  std::latch may_go{1};
  core.serve("first", [&](const int& x) {
    if (x < 0) may_go.wait();  // one worker: the post waits in the queue
    return x;
  });
  core.serve("last", [](const int& x) { return x; }, {.calls_per_client = 1});
  std::jthread blocker{[first = core.chain<int, int>("first")] { EXPECT_EQ(first(-1), -1); }};
  ASSERT_TRUE(MappedTopic::within(10s, [&] { return listed(core, "first")->requests_from_callers == 1; }));
  auto last = core.chain<int, int>("last");
  {
    shm::Core old_server{core.domain()};
    old_server.serve("middle", [](const int& x) { return x; });
    ASSERT_TRUE((core.chain<int, int>("first") | core.chain<int, int>("middle") | last).post(1));
  }
  shm::Core new_server{core.domain()};
  new_server.serve("middle", [](const int& x) { return x; }, {.max_clients = 8});  // made anew
  may_go.count_down();
  blocker.join();
  std::expected<int, Error> direct = std::unexpected(Error{});
  EXPECT_TRUE(MappedTopic::within(10s, [&] { return (direct = last.call(3)).has_value(); })) << direct.error().describe();
}

// A server takes a service, then sets its limits: a caller that binds in
// between finds no timeout set yet, and waits the default, not nothing.
TEST_F(ServiceTest, ACallToAServiceWhoseLimitsAreNotSetYetWaitsTheDefault) {
  core.serve("busy", [](const int& x) {
    const auto until = Clock::now() + 5ms;  // a block that takes a while (work, not a wait for anything)
    while (Clock::now() < until) {
    }
    return x + 1;
  });
  MappedService{core.domain(), "busy"}.header().timeout_ns.store(0);
  auto busy = core.chain<int, int>("busy");
  auto answered = busy.call(1);
  ASSERT_TRUE(answered) << answered.error().describe();
  EXPECT_EQ(*answered, 2);
}

TEST_F(ServiceTest, ManyThreadsOnOneHandleEachGetTheirOwnAnswer) {
  core.serve("echo", [](const std::uint64_t& x) { return x * 3; }, {.workers = 2, .calls_per_client = 8});
  auto echo = core.chain<std::uint64_t, std::uint64_t>("echo");
  std::atomic<int> wrong{0};
  {
    std::vector<std::jthread> threads;
    for (std::uint64_t t = 0; t < 4; ++t)
      threads.emplace_back([&, t] {
        for (std::uint64_t i = 0; i < 5000; ++i) {
          const auto x = t * 1'000'000 + i;
          auto got = echo.call(x);
          if (!got || *got != 3 * x) ++wrong;
        }
      });
  }
  EXPECT_EQ(wrong, 0);
}

TEST_F(ServiceTest, AnIdleServiceCostsNoCpu) {
  core.serve("idle", plan, {.workers = 4});
  ASSERT_TRUE((core.chain<Pose, Path>("idle").call({1, 1})));
  rusage before{}, after{};
  ::getrusage(RUSAGE_SELF, &before);
  std::this_thread::sleep_for(1s);  // the measured second of silence
  ::getrusage(RUSAGE_SELF, &after);
  auto cpu = [](const rusage& r) {
    return std::chrono::seconds{r.ru_utime.tv_sec + r.ru_stime.tv_sec} +
           std::chrono::microseconds{r.ru_utime.tv_usec + r.ru_stime.tv_usec};
  };
  EXPECT_LT(cpu(after) - cpu(before), 20ms) << "four idle workers sleep";
}

TEST_F(ServiceTest, AServiceChainWorksInCombinatorsAndAfterASource) {
  liberty::Core local;
  core.serve("double", [](const int& x) { return 2 * x; });
  auto doubled = core.chain<int, int>("double");
  auto guarded = if_then_else(local, [](const int& x) { return x > 0; }, doubled, local.chain([](int x) { return -x; }));
  EXPECT_EQ(guarded(4), 8);
  EXPECT_EQ(guarded(-4), 4);
  EXPECT_EQ(foreach(local, doubled)({1, 2}), (std::vector<int>{2, 4}));
  EXPECT_EQ(repeat(local, doubled, [](const int& x) { return x > 50; })(1), 64);
  Event<int> ticks;
  auto outputs = core.source(ticks, "ticks") | doubled;
  auto reader = outputs.subscribe();
  ticks.emit(21);
  auto got = reader.read_for(5s);
  ASSERT_TRUE(got) << got.error().describe();
  EXPECT_EQ(got->value, 42);
}

}  // namespace
}  // namespace prime::test
