// Shm at its boundaries: what another process (or user) leaves in shared
// memory, and sizes a caller asks for, are input. Whatever they are, no
// write lands outside a cell or a segment, no read goes past a bound, no
// loop runs without bound, and each is an error that names what was wrong.
#include <gtest/gtest.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <unistd.h>

#include <array>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <fcntl.h>
#include <future>
#include <limits>
#include <new>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "prime/shm.hpp"
#include "prime/shm/detail/segment.hpp"
#include "prime/shm/detail/service_layout.hpp"
#include "shm/domain.hpp"
#include "shm/mapped_topic.hpp"
#include "support/failure.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

struct Small {
  std::uint64_t value;
};
struct Large {
  std::array<std::byte, 1 << 16> bytes;
};

class Boundary : public ::testing::Test {
 protected:
  shm::Core core{unique_domain("boundary"), {.participant = "test"}};

  [[nodiscard]] std::string path_of(const std::string& kind, const std::string& name) const {
    return std::string{"/dev/shm/"} + shm::detail::segment_name(core.domain(), kind, name);
  }
};

// Linking raw chains (a tool's) of services whose types differ is refused
// when the link is made: the first one's output would be written into a
// cell made for the second one's smaller request. A service of Bytes takes
// any type, and a reply too large for its cell is an error of that call.
TEST_F(Boundary, LinkingServicesWhoseTypesDifferIsRefusedWhenLinked) {
  core.serve("a", [](const Small&) { return Large{}; });
  core.serve("b", [](const Small& s) { return s; });
  EXPECT_TRUE(fails_with([&] { (void)shm::link(core.raw_chain("a"), core.raw_chain("b")); }, Errc::type_mismatch,
                         "cannot link service 'a', which gives prime::test::{anonymous}::Large"));
  auto fine = shm::link(core.raw_chain("b"), core.raw_chain("b"));  // same types: linked
  const Small seven{7};
  const auto out = fine.call(std::as_bytes(std::span{&seven, 1}));
  ASSERT_TRUE(out) << out.error().describe();
  ASSERT_EQ(out->size(), sizeof(Small));

  // A service of Bytes takes any reply, each write checked against its cell.
  auto size_of = [](std::span<const std::byte> b) { return Small{b.size()}; };
  core.serve("sizes", size_of, {.max_request_size = sizeof(Large), .max_reply_size = sizeof(Small)});
  core.serve("tiny", size_of, {.max_request_size = 16, .max_reply_size = sizeof(Small)});
  const auto sized = shm::link(core.raw_chain("a"), core.raw_chain("sizes")).call(std::as_bytes(std::span{&seven, 1}));
  ASSERT_TRUE(sized) << sized.error().describe();
  ASSERT_EQ(sized->size(), sizeof(Small));
  Small answer{};
  std::memcpy(&answer, sized->data(), sizeof answer);
  EXPECT_EQ(answer.value, sizeof(Large));
  const auto too_big = shm::link(core.raw_chain("a"), core.raw_chain("tiny")).call(std::as_bytes(std::span{&seven, 1}));
  ASSERT_FALSE(too_big);
  EXPECT_EQ(too_big.error().code, Errc::too_large) << too_big.error().describe();
}

// A service whose header says its cells are smaller than its types (a
// foreign or broken program, laid out consistently) is refused by a client
// before it writes a request there.
TEST_F(Boundary, AClientRefusesCellsSmallerThanItsTypes) {
  std::atomic<int> served{0};
  core.serve("small", [&](const Large&) {
    ++served;
    return Small{1};
  });
  {
    auto segment = shm::detail::Segment::open_existing(shm::detail::segment_name(core.domain(), "service", "small"));
    ASSERT_TRUE(segment);
    auto& h = *std::launder(reinterpret_cast<shm::detail::ServiceHeader*>(segment->data()));
    const shm::detail::ServiceGeometry shrunk{64, h.max_reply_size, h.max_clients, h.calls_per_client};
    h.max_request_size = shrunk.max_request_size;  // a layout that follows from it, within the segment
    h.cell_stride = shrunk.cell_stride();
    h.request_offset = shrunk.request_offset();
    h.reply_offset = shrunk.reply_offset();
    h.tail_offset = shrunk.tail_offset();
  }
  shm::Core client{core.domain(), {.participant = "client"}};
  const auto answer = client.chain<Large, Small>("small").call(Large{});
  ASSERT_FALSE(answer) << "a 64 KiB request written into a 64-byte cell";
  EXPECT_EQ(answer.error().code, Errc::damaged) << answer.error().describe();
  EXPECT_NE(answer.error().message.find("64-byte requests"), std::string::npos) << answer.error().describe();
  EXPECT_EQ(served.load(), 0);
}

// A segment made by another user, or with more permission bits than the
// domain asks for, is refused, naming the file and its owner or mode:
// another local user could make a domain's files before its participants
// come, and map what they then write.
TEST(BoundarySegments, ASegmentOfAnotherUserOrWithAWiderModeIsRefused) {
  const auto domain = unique_domain("owner");
  const auto registry = std::string{"/dev/shm/"} + shm::detail::segment_name(domain, "registry", "");
  const int fd = ::open(registry.c_str(), O_CREAT | O_EXCL | O_RDWR, 0600);
  ASSERT_GE(fd, 0);
  ASSERT_EQ(::fchmod(fd, 0666), 0);  // as umask would not let open() give
  EXPECT_TRUE(fails_with([&] { shm::Core core{domain}; }, Errc::unreachable, "its mode 0666 allows more than the 0600"));
  EXPECT_TRUE(fails_with([&] { shm::Core core{domain}; }, Errc::unreachable, registry));
  if (::geteuid() == 0) {  // only root can give a file away
    ASSERT_EQ(::fchmod(fd, 0600), 0);
    ASSERT_EQ(::fchown(fd, 65534, 65534), 0);
    EXPECT_TRUE(fails_with([&] { shm::Core core{domain}; }, Errc::unreachable, "it belongs to uid 65534, not to uid 0"));
    shm::Core trusting{domain, {.owner = 65534}};  // a domain whose options name that owner takes it
    EXPECT_EQ(trusting.registry().participants.size(), 1u);
    // It makes no segment of its own there: that would be root's, and refused.
    EXPECT_TRUE(fails_with([&] { (void)trusting.publisher<int>("theirs"); }, Errc::not_found,
                           "is not there, and only uid 65534 (DomainOptions::owner) makes this domain's segments"));
    EXPECT_EQ(segments_of(domain), 1) << "nothing made that it would then refuse, and leave";
  }
  ::close(fd);
  ::unlink(registry.c_str());
}

// A domain whose registry's name would be shortened with a hash (tools
// could not read it back from /dev/shm) is refused, as is a name holding a
// NUL (never found again in the registry: a new entry on every open).
TEST(BoundaryNames, ADomainTooLongToReadBackAndANameWithANulAreRefused) {
  EXPECT_TRUE(fails_with([] { shm::Core core{unique_domain("long") + std::string(220, 'x')}; }, Errc::invalid_argument,
                         "too long (2"));
  shm::Core core{unique_domain("nul")};
  const std::string with_nul{"a\0b", 3};
  EXPECT_TRUE(fails_with([&] { (void)core.publisher<int>(with_nul); }, Errc::invalid_argument, "no control character"));
  EXPECT_TRUE(core.registry().topics.empty());
}

// bounded_string and bounded_vector read within their capacity whatever
// count the bytes hold (another process wrote them).
TEST(BoundaryMessages, BoundedTypesNeverReadPastTheirCapacity) {
  bounded_string<8> text{"abc"};
  bounded_vector<float, 4> values{1.f, 2.f};
  const std::uint64_t forged = 1ull << 30;
  std::memcpy(reinterpret_cast<std::byte*>(&text) + bounded_string<8>::size_offset(), &forged, sizeof(std::uint32_t));
  std::memcpy(reinterpret_cast<std::byte*>(&values) + bounded_vector<float, 4>::size_offset(), &forged, sizeof forged);
  EXPECT_EQ(text.size(), 8u);
  EXPECT_EQ(text.str().size(), 8u);
  EXPECT_FALSE(text.valid());
  EXPECT_EQ(values.size(), 4u);
  EXPECT_EQ(values.span().size(), 4u);
  EXPECT_EQ(std::distance(values.begin(), values.end()), 4);
  EXPECT_FALSE(values.valid());
  EXPECT_TRUE((bounded_string<8>{"abc"}.valid()));
}

// Ring entries naming samples far ahead of anything published: a read ends
// at its deadline with Errc::damaged, not after walking the ring for
// minutes one sequence at a time.
TEST_F(Boundary, RingEntriesFarAheadOfTheHeadAreDamageAndEndTheReadAtOnce) {
  const shm::TopicQos qos{.capacity = 8};
  auto publisher = core.publisher<int>("forged", qos);
  auto reader = core.subscribe<int>("forged", {}, qos).subscribe();
  auto batches = core.subscribe<int>("forged", {}, qos).batches();
  ASSERT_TRUE(publisher.publish(1));
  ASSERT_TRUE(reader.read_for(1s));
  ASSERT_FALSE(batches.read(8, deadline_after(1s))->empty());
  const MappedTopic mapped{core.domain(), "forged"};
  for (std::uint64_t seq = 1; seq < 9; ++seq)  // each naming a sample 2^39 - 8 past its own, in chunk 0
    mapped.ring(seq).store(shm::detail::RingEntry::pack(seq + (1ull << 39) - 8, 0));
  const auto started = Clock::now();
  const auto read = reader.read_for(100ms);
  ASSERT_FALSE(read);
  EXPECT_EQ(read.error().code, Errc::damaged) << read.error().describe();
  EXPECT_NE(read.error().message.find("topic 'forged': its shared memory is damaged (the ring entry for sample 1"),
            std::string::npos)
      << read.error().describe();
  const auto batch = batches.read(8, deadline_after(100ms));
  ASSERT_FALSE(batch);
  EXPECT_EQ(batch.error().code, Errc::damaged) << batch.error().describe();
  EXPECT_LT(Clock::now() - started, 30s) << "bounded: not a walk of 2^39 sequences";
  for (std::uint64_t seq = 1; seq < 9; ++seq)  // as a new topic's: nothing published there
    mapped.ring(seq).store(shm::detail::RingEntry::pack(seq - 8, shm::detail::kNoChunk));
  ASSERT_TRUE(publisher.publish(2));  // sample 1 again, published for real: read as ever
  const auto next = reader.read_for(1s);
  ASSERT_TRUE(next) << next.error().describe();
  EXPECT_EQ(*next->value, 2);
}

// A worker reading a damaged topic (here: forward) reports the damage once
// on errors() and goes on: the next sample published for real reaches it.
// A damaged ring used to end the worker, and every chain linked to it,
// without a word.
TEST_F(Boundary, DamageReachesErrorsOnceAndAWorkerReadsOn) {
  const shm::TopicQos qos{.capacity = 8};
  auto publisher = core.publisher<int>("forged", qos);
  auto errors = core.errors().subscribe();
  struct Seen {  // the worker's, kept by it: it may outlive a test that failed
    std::promise<void> first;
    std::promise<int> after_damage;
    int count = 0;
  };
  auto seen = std::make_shared<Seen>();
  auto first = seen->first.get_future();
  auto next = seen->after_damage.get_future();
  forward(core.subscribe<int>("forged", {}, qos), [seen](const shm::View<int>& v, Clock::time_point) {
    if (++seen->count == 1) seen->first.set_value();
    else if (seen->count == 2) seen->after_damage.set_value(*v);
  });
  ASSERT_TRUE(publisher.publish(1));
  ASSERT_EQ(first.wait_for(10s), std::future_status::ready);
  const MappedTopic mapped{core.domain(), "forged"};
  ASSERT_TRUE(mapped.a_subscriber_sleeps()) << "the worker waits for the next sample";
  for (std::uint64_t seq = 1; seq < 9; ++seq)
    mapped.ring(seq).store(shm::detail::RingEntry::pack(seq + (1ull << 39) - 8, 0));
  mapped.header().data.ring_always();  // as a publisher would, after writing them
  const auto said = errors.read_for(10s);
  ASSERT_TRUE(said) << said.error().describe();
  EXPECT_EQ(said->value.code, Errc::damaged) << said->value.describe();
  for (std::uint64_t seq = 1; seq < 9; ++seq)
    mapped.ring(seq).store(shm::detail::RingEntry::pack(seq - 8, shm::detail::kNoChunk));
  ASSERT_TRUE(publisher.publish(2));
  ASSERT_EQ(next.wait_for(10s), std::future_status::ready) << "the worker ended at the damage";
  EXPECT_EQ(next.get(), 2);
  EXPECT_FALSE(errors.try_read()) << "the same damage is reported once, not on every read";
}

// Sizes whose product wraps around are refused one by one, by name, before
// any memory is reserved (a topic of 12 KiB with messages of 2^58 bytes
// had its publisher write outside its segment).
TEST_F(Boundary, QosSizesThatWouldWrapAroundAreRefused) {
  EXPECT_TRUE(fails_with([&] { (void)core.publisher<shm::Bytes>("huge", {.capacity = 54, .max_message_size = (1ull << 58) - 128}); },
                         Errc::invalid_argument, "topic 'huge': QoS out of bounds"));
  EXPECT_TRUE(fails_with([&] { (void)core.publisher<int>("held", {.max_held = std::size_t{1} << 40}); },
                         Errc::invalid_argument, "max_held 1099511627776"));
  EXPECT_TRUE(fails_with([&] { (void)core.publisher<int>("ring", {.capacity = std::size_t{1} << 40}); },
                         Errc::invalid_argument, "a capacity of 1099511627776"));
  EXPECT_TRUE(fails_with(
      [&] {
        (void)core.serve("echo", [](std::span<const std::byte> b) { return std::vector<std::byte>(b.begin(), b.end()); },
                         {.max_request_size = std::numeric_limits<std::size_t>::max() - 10, .max_reply_size = 64});
      },
      Errc::invalid_argument, "service 'echo': QoS out of bounds: requests of 18446744073709551605 bytes"));
  EXPECT_EQ(segments_of(core.domain()), 1) << "nothing but the registry was made";
}

// A header whose counts would have each subscriber size its own state past
// what the segment holds (max_held near 2^24 with no subscriber slots: 1.2
// GB per subscriber) is damage, refused before anything is allocated.
TEST_F(Boundary, AHeaderCannotMakeASubscriberAllocatePastItsSegment) {
  auto publisher = core.publisher<int>("held");
  {
    const MappedTopic mapped{core.domain(), "held"};
    auto& h = mapped.header();
    h.max_subscribers = 0;
    h.max_held = (1u << 24) - 2;
    h.chunk_count = h.capacity + 2;  // the layout follows from it
  }
  shm::Core other{core.domain(), {.participant = "other"}};
  EXPECT_TRUE(fails_with([&] { (void)other.subscribe<int>("held"); }, Errc::damaged, "0 subscriber slots"));
}

// A segment whose header reads as not set up (its magic zeroed) is set up
// again by the next opener, but never shrunk under those who map it (each
// would die of SIGBUS at its first access past the new end).
TEST_F(Boundary, ASegmentSetUpAgainIsNeverShrunkUnderItsUsers) {
  const shm::TopicQos big{.capacity = 1024, .max_message_size = 4096};
  auto publisher = core.publisher<shm::Bytes>("zeroed", big);
  auto user = shm::detail::Segment::open_existing(shm::detail::segment_name(core.domain(), "topic", "zeroed"));
  ASSERT_TRUE(user);  // a participant's mapping of all of it
  struct stat before {};
  ASSERT_EQ(::stat(path_of("topic", "zeroed").c_str(), &before), 0);
  MappedTopic{core.domain(), "zeroed"}.header().magic.store(0);
  shm::Core other{core.domain(), {.participant = "other"}};
  const shm::TopicQos small{.capacity = 4, .max_message_size = 64};
  auto reader = other.subscribe<shm::Bytes>("zeroed", {}, small).subscribe();
  struct stat after {};
  ASSERT_EQ(::stat(path_of("topic", "zeroed").c_str(), &after), 0);
  ASSERT_GE(after.st_size, before.st_size) << "shrunk under a live publisher";
  std::memset(user->data() + user->size() - 4096, 1, 4096);  // its last page is still there
}

// "Forever" (milliseconds::max()) stays forever: a `block` publisher waits
// for its reader, and a call waits for its answer, instead of giving up at
// once (it was converted to -1 ms).
TEST_F(Boundary, AWaitOfMillisecondsMaxWaitsAsLongAsItTakes) {
  const shm::TopicQos qos{.capacity = 4, .overflow = Overflow::block, .block_timeout = std::chrono::milliseconds::max()};
  auto publisher = core.publisher<int>("slow", qos);
  auto reader = core.subscribe<int>("slow", {}, qos).subscribe();
  for (int i = 0; i < 4; ++i) ASSERT_TRUE(publisher.publish(i));
  auto fifth = std::async(std::launch::async, [&] { return publisher.publish(4); });
  struct Drain {  // a failed assertion still frees the publisher (the future waits for it)
    decltype(fifth)& publish;
    decltype(reader)& from;
    ~Drain() {
      while (publish.valid() && publish.wait_for(0s) != std::future_status::ready) (void)from.try_read();
    }
  } drain{fifth, reader};
  ASSERT_TRUE((MappedTopic{core.domain(), "slow"}.the_publisher_sleeps())) << "a full ring: the publisher waits";
  for (int i = 0; i < 5; ++i) {
    const auto got = reader.read_for(10s);
    ASSERT_TRUE(got) << got.error().describe();
    EXPECT_EQ(*got->value, i) << "nothing dropped";
  }
  EXPECT_TRUE(fifth.get());

  std::atomic<bool> entered{false}, go{false};
  core.serve("patient", [&](const Small& s) {
    entered = true;
    while (!go) std::this_thread::yield();
    return s;
  });
  auto patient = core.chain<Small, Small>("patient", {.timeout = std::chrono::milliseconds::max()});
  auto answer = std::async(std::launch::async, [&] { return patient.call(Small{5}); });
  struct Go {  // a failed assertion still lets the service answer (the future waits for it)
    std::atomic<bool>& go;
    ~Go() { go = true; }
  } release{go};
  while (!entered && answer.wait_for(0s) != std::future_status::ready) std::this_thread::yield();
  go = true;
  const auto got = answer.get();
  ASSERT_TRUE(got) << got.error().describe();
  EXPECT_EQ(got->value, 5u);
}

}  // namespace
}  // namespace prime::test
