// Shm across real processes: the peers are the shm_peer program, started
// with posix_spawn and killed with SIGKILL at known points.
#include <gtest/gtest.h>
#include <sys/wait.h>
#include <unistd.h>

#include <chrono>
#include <cstdlib>
#include <optional>
#include <cstdint>
#include <fstream>
#include <string>
#include <vector>

#include "prime/shm.hpp"
#include "prime/shm/detail/asymmetric_fence.hpp"
#include "shm/domain.hpp"
#include "shm/mappings.hpp"
#include "shm/mapped_topic.hpp"
#include "shm/messages.hpp"
#include "shm/peer_process.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

TEST(ShmProcesses, ASampleFromAnotherProcessIsReadInPlaceInTheSharedSegment) {
  const auto domain = unique_domain("zero-copy");
  shm::Core core{domain};
  auto reader = core.subscribe<std::uint64_t>("numbers").subscribe();
  PeerProcess peer{{"publish", domain, "numbers", "7", "1", "64", "drop"}};
  ASSERT_TRUE(peer.says("published"));
  auto sample = reader.read_for(5s);
  ASSERT_TRUE(sample) << sample.error().describe();
  EXPECT_EQ(*sample->value, 7u);
  EXPECT_TRUE(inside_mapping_of("numbers", sample->value.get())) << "read where the other process wrote it";
}

// A child forked after its parent joined shares the parent's lease (the
// lock belongs to the open file description both hold): its copy of the
// participant going must not release it, or the live parent is taken for
// dead and its slots are cleared under it.
TEST(ShmProcesses, AChildForkedAfterJoiningLeavesTheParentsLeaseAlone) {
  const auto domain = unique_domain("fork");
  std::optional<shm::Core> core{std::in_place, domain, shm::DomainOptions{.participant = "parent"}};
  const pid_t child = ::fork();
  ASSERT_GE(child, 0);
  if (child == 0) {
    core.reset();  // the child's copy of the parent's participant goes, as at a return from main
    std::_Exit(0);
  }
  int status = 0;
  ASSERT_EQ(::waitpid(child, &status, 0), child);
  ASSERT_TRUE(WIFEXITED(status) && WEXITSTATUS(status) == 0);
  shm::Core other{domain, {.participant = "other"}};
  bool parent_alive = false;
  for (const auto& p : other.registry().participants) parent_alive |= p.name == "parent" && p.alive;
  EXPECT_TRUE(parent_alive) << "the parent, alive, is still seen alive";
}

TEST(ShmProcesses, APublisherKilledMidLoanLeavesSubscribersRunningAndARestartedOneContinues) {
  const auto domain = unique_domain("killed-publisher");
  shm::Core core{domain};
  auto reader = core.subscribe<std::uint64_t>("odom").subscribe();
  {
    PeerProcess first{{"loan_and_hang", domain, "odom", "10", "64"}};
    ASSERT_TRUE(first.says("loaned"));
    first.kill9();
  }
  for (std::uint64_t i = 0; i < 10; ++i) {
    auto sample = reader.read_for(5s);
    ASSERT_TRUE(sample) << sample.error().describe();
    EXPECT_EQ(*sample->value, i);
  }
  EXPECT_FALSE(reader.try_read()) << "the unpublished loan never reaches a subscriber";

  PeerProcess second{{"publish", domain, "odom", "100", "10", "64", "drop"}};
  ASSERT_TRUE(second.says("published"));
  EXPECT_EQ(second.exit_code(), 0) << "the restarted publisher took the topic over";
  for (std::uint64_t i = 0; i < 10; ++i) {
    auto sample = reader.read_for(5s);
    ASSERT_TRUE(sample) << sample.error().describe();
    EXPECT_EQ(*sample->value, 100 + i);
    EXPECT_EQ(sample->value.sequence(), 10 + i) << "the topic goes on where it stopped";
  }
  EXPECT_EQ(reader.lost(), 0u);
}

// A publisher killed with chunks on their way out of the ring strands none:
// its successor's recovery frees them. A light publisher gives them back
// several at a time, so some have left the ring but are still its own; a
// full one evicts each at once, to its spares.
void expect_a_publisher_killed_with_chunks_leaving_to_strand_none(const std::string& fence) {
  if (fence == "light" && !shm::detail::light_fences())
    GTEST_SKIP() << "membarrier(2) is refused here, so a light publisher fences fully";
  const auto domain = unique_domain("killed-leaving");
  shm::Core core{domain};
  const shm::TopicQos qos{.capacity = 4};
  auto reader = core.subscribe<std::uint64_t>("odom", {}, qos).subscribe();
  PeerProcess first{{"loan_and_hang", domain, "odom", "103", "4", fence}};
  ASSERT_TRUE(first.says("loaned"));
  const MappedTopic mapped{domain, "odom"};
  const auto at_kill = mapped.census();
  EXPECT_EQ(at_kill.ring_only, 4u);
  ASSERT_GT(at_kill.other, 1u) << "the loan, and chunks out of the ring (" << fence
                               << ": not yet given back, or spares), when it dies";
  first.kill9();
  {
    auto second = core.publisher<std::uint64_t>("odom", qos);
    for (std::uint64_t i = 0; i < 3; ++i) ASSERT_TRUE(second.publish(i));
  }
  const auto census = mapped.census();
  EXPECT_EQ(census.ring_only, 4u);
  EXPECT_EQ(census.other, 0u) << "no chunk is left held by the dead publisher";
}

TEST(ShmProcesses, ALightPublisherKilledWhileChunksLeaveTheRingStrandsNone) {
  expect_a_publisher_killed_with_chunks_leaving_to_strand_none("light");
}

TEST(ShmProcesses, AFullPublisherKilledWithChunksTakenFromTheRingStrandsNone) {
  expect_a_publisher_killed_with_chunks_leaving_to_strand_none("full");
}

// Publishes sample 0 for `holder` (a peer subscribing to the topic, which
// says so) and waits until it holds it.
::testing::AssertionResult holds_the_first_sample(PeerProcess& holder, shm::Publisher<std::uint64_t>& publisher) {
  if (!holder.says("subscribed")) return ::testing::AssertionFailure() << "the peer did not subscribe";
  if (!publisher.publish(0)) return ::testing::AssertionFailure() << "sample 0 was not published";
  if (!holder.says("holding")) return ::testing::AssertionFailure() << "the peer took no sample";
  return ::testing::AssertionSuccess();
}

// `how`: the holder takes one view ("view") or a batch the cursor keeps ("views").
void expect_a_killed_holder_not_to_stall_a_block_publisher(const std::string& how) {
  const auto domain = unique_domain("killed-subscriber-block");
  shm::Core core{domain};
  const shm::TopicQos qos{.capacity = 4, .overflow = Overflow::block, .block_timeout = 30s};
  auto publisher = core.publisher<std::uint64_t>("cmds", qos);
  auto live = core.subscribe<std::uint64_t>("cmds", {}, qos).subscribe();
  PeerProcess holder{{"hold", domain, "cmds", "4", "block", how}};
  ASSERT_TRUE(holds_the_first_sample(holder, publisher));
  holder.kill9();

  const auto start = std::chrono::steady_clock::now();
  std::uint64_t received = 0;
  for (std::uint64_t i = 1; i <= 100; ++i) {
    ASSERT_TRUE(publisher.publish(i));
    while (auto s = live.try_read()) EXPECT_EQ(*s->value, received++);
  }
  EXPECT_LT(std::chrono::steady_clock::now() - start, 10s)
      << "the dead subscriber was reclaimed, not waited for until the 30 s block timeout";
  while (auto s = live.try_read()) EXPECT_EQ(*s->value, received++);
  EXPECT_EQ(received, 101u);
  EXPECT_EQ(core.registry().topics.at(0).subscriber_pids.size(), 1u) << "only the live subscriber is left";
}

TEST(ShmProcesses, ASubscriberKilledWhileHoldingASampleDoesNotStallABlockPublisher) {
  expect_a_killed_holder_not_to_stall_a_block_publisher("view");
}

TEST(ShmProcesses, ASubscriberKilledWithABatchOutDoesNotStallABlockPublisher) {
  expect_a_killed_holder_not_to_stall_a_block_publisher("views");
}

// A drop_oldest topic "scan" this process publishes, and a peer process
// that subscribed, took sample 0, and was killed with -9 holding it.
class ShmKilledHolder : public ::testing::Test {
 protected:
  void SetUp() override {
    ASSERT_TRUE(holds_the_first_sample(holder, publisher));
    holder.kill9();
  }
  const std::string domain = unique_domain("killed-holder");
  shm::Core core{domain};
  shm::Publisher<std::uint64_t> publisher = core.publisher<std::uint64_t>("scan", {.capacity = 4});
  PeerProcess holder{{"hold", domain, "scan", "4", "drop", "view"}};
};

TEST_F(ShmKilledHolder, LeavesADropOldestPublisherUnaffected) {
  for (std::uint64_t i = 1; i <= 10000; ++i) ASSERT_TRUE(publisher.publish(i)) << i;
  EXPECT_EQ(core.reclaim(), 1u) << "the dead subscriber's slot (and the sample it held) is reclaimed";
}

// A process killed while it cleared the killed holder's slot leaves the
// slot naming it as the clearer, with some of the holder's holds still set:
// the state written below (a clearer dies between two steps at any time; no
// test can stop it there). A slot whose clearer lives is left to it; one
// whose clearer died is cleared again by the next participant that looks,
// and is not lost for as long as the topic lives.
TEST_F(ShmKilledHolder, WhoseSlotsClearerWasKilledTooIsClearedAgain) {
  const MappedTopic mapped{domain, "scan"};
  auto& h = mapped.header();
  std::size_t slot = 0;
  while (slot < shm::detail::kSlots && h.subscribers[slot].owner.load() == 0) ++slot;
  ASSERT_LT(slot, shm::detail::kSlots);
  const auto dead = h.subscribers[slot].owner.load();
  const auto held_by_slot = [&] {
    std::size_t n = 0;
    for (std::size_t c = 0; c < h.chunk_count; ++c) n += (mapped.holders(c) >> slot) & 1;
    return n;
  };
  ASSERT_EQ(held_by_slot(), 1u);

  h.subscribers[slot].owner.store(shm::detail::kReclaimingBit | h.publisher.load());  // a live clearer: this process
  EXPECT_EQ(core.reclaim(), 0u) << "a slot a live participant clears is left to it";
  h.subscribers[slot].owner.store(shm::detail::kReclaimingBit | dead);  // a clearer killed half way
  EXPECT_EQ(core.reclaim(), 1u);
  EXPECT_EQ(h.subscribers[slot].owner.load(), 0u) << "the slot is free again";
  EXPECT_EQ(held_by_slot(), 0u) << "and so is the sample the dead subscriber held";
  auto reader = core.subscribe<std::uint64_t>("scan", {}, {.capacity = 4}).subscribe();
  ASSERT_TRUE(publisher.publish(1));
  auto got = reader.try_read();
  ASSERT_TRUE(got);
  EXPECT_EQ(*got->value, 1u);
}

// Reads what a publisher process overwrites heavily, one sample at a time
// or (`batches`) every sample available in one read_some; the publisher
// publishes one at a time or (`published_in_batches`) up to a ring at once,
// when the chunks leaving the ring are evicted after the head's fence. With
// `block`, the reader is passed over whenever it stops, and lapped all the
// same, while it holds what it reads and the publisher waits for it.
void expect_no_torn_sample(bool batches, bool published_in_batches = false, bool block = false) {
  const auto domain = unique_domain("torn");
  shm::Core core{domain};
  const auto qos = block ? kCheckedBlockQos : kCheckedQos;
  auto topic = core.subscribe<Checked>("checked", {}, qos);
  auto reader = topic.subscribe();
  const MappedTopic mapped{domain, "checked"};
  std::vector<std::string> args{"checksum_publish", domain, "checked", "200000"};
  if (published_in_batches) args.emplace_back(block ? "block_batches" : "batches");
  PeerProcess publisher{args};
  std::uint64_t received = 0, torn = 0, last = 0;
  std::vector<Sample<shm::View<Checked>>> taken;
  auto next = [&]() -> std::optional<Sample<shm::View<Checked>>> {
    if (!batches) return reader.try_read();
    if (taken.empty() && !reader.read_some(taken, qos.max_held, Clock::now())) return std::nullopt;
    auto s = std::move(taken.front());
    taken.erase(taken.begin());
    return s;
  };
  bool done = false;
  while (!done) {
    done = publisher.exit_code(0ms).has_value();  // drain once more after it ends
    while (auto s = next()) {
      ++received;
      if (!check(*s->value)) ++torn;
      EXPECT_GE(s->value->seq, last);
      last = s->value->seq;
      if (received % 1000 == 0) {
        // Let the publisher lap this reader (a ring of 4): overwriting is
        // what the test is about, so it is made to happen, not hoped for.
        const auto lap = s->value->seq + 3 * qos.capacity;
        MappedTopic::within(10s, [&] { return mapped.header().head.load() > lap || publisher.exit_code(0ms); });
      }
    }
  }
  EXPECT_EQ(torn, 0u) << "of " << received << " samples";
  EXPECT_GT(received, 0u);
  EXPECT_GT(reader.lost(), 0u) << "the publisher lapped the reader: the test exercised overwriting";
  EXPECT_EQ(received + reader.lost(), 200000u) << "every sample is either delivered whole or counted lost";
}

TEST(ShmProcesses, NoTornSampleIsEverDeliveredUnderHeavyOverwrite) { expect_no_torn_sample(false); }

TEST(ShmProcesses, NoTornSampleIsEverDeliveredUnderHeavyOverwriteToABatchReader) { expect_no_torn_sample(true); }

TEST(ShmProcesses, NoTornSampleIsEverDeliveredUnderHeavyOverwriteInBatches) { expect_no_torn_sample(false, true); }

TEST(ShmProcesses, NoTornSampleIsEverDeliveredUnderHeavyOverwriteInBatchesToABatchReader) {
  expect_no_torn_sample(true, true);
}

TEST(ShmProcesses, NoTornSampleIsEverDeliveredWhenABlockPublisherInBatchesLapsAPassedOverReader) {
  expect_no_torn_sample(false, true, true);
}

TEST(ShmProcesses, NoTornSampleIsEverDeliveredWhenABlockPublisherInBatchesLapsAPassedOverBatchReader) {
  expect_no_torn_sample(true, true, true);
}

// A publisher process runs `role` (sequence_publish or batch_publish): this
// process reads 0..count-1 in batches, of views (read_some) or as Views
// (`views`), and checks each.
void expect_every_message_in_order(const std::string& role, bool views = false) {
  const auto domain = unique_domain("sequence");
  shm::Core core{domain};
  auto topic = core.subscribe<std::uint64_t>("seq", {}, kSequenceQos);
  auto reader = topic.subscribe();
  auto batches = topic.batches();
  PeerProcess publisher{{role, domain, "seq", std::to_string(PRIME_SHM_SEQUENCE_COUNT)}};
  ASSERT_TRUE(publisher.says("ready"));
  std::uint64_t expected = 0, wrong = 0;
  std::vector<Sample<shm::View<std::uint64_t>>> batch;
  while (expected < PRIME_SHM_SEQUENCE_COUNT) {
    if (views) {
      auto got = batches.read(256, Clock::now() + 10s);
      ASSERT_TRUE(got) << got.error().describe() << " after " << expected << " messages";
      for (std::size_t i = 0; i < got->size(); ++i) {
        if ((*got)[i] != expected || got->sequence(i) != expected) ++wrong;
        ++expected;
      }
      continue;
    }
    batch.clear();
    auto got = reader.read_some(batch, 256, Clock::now() + 10s);
    ASSERT_TRUE(got) << got.error().describe() << " after " << expected << " messages";
    for (const auto& s : batch) {
      if (*s.value != expected || s.value.sequence() != expected) ++wrong;
      ++expected;
    }
  }
  EXPECT_EQ(wrong, 0u);
  EXPECT_EQ((views ? batches.lost() : reader.lost()), 0u);
  EXPECT_EQ(publisher.exit_code(), 0);
  EXPECT_TRUE(views ? batches.try_read(1).empty() : !reader.try_read()) << "nothing beyond the last message";
}

TEST(ShmProcesses, BlockDeliversEveryMessageAcrossProcessesWithNoGapOrDuplicate) {
  expect_every_message_in_order("sequence_publish");
}

TEST(ShmProcesses, BatchesOfEverySizeDeliverEveryMessageAcrossProcessesInOrder) {
  expect_every_message_in_order("batch_publish");
}

TEST(ShmProcesses, BatchesReadAsViewsDeliverEveryMessageAcrossProcessesInOrder) {
  expect_every_message_in_order("batch_publish", true);
}

TEST(ShmProcesses, SegmentsLeftByADeadRunAreCleanedWhenTheDomainStarts) {
  const auto domain = unique_domain("stale");
  {
    PeerProcess crashed{{"leave_segments", domain, "old"}};
    ASSERT_TRUE(crashed.says("created"));
    crashed.kill9();
  }
  ASSERT_EQ(segments_of(domain), 2) << "the killed run left its registry and topic behind";
  shm::Core core{domain};
  EXPECT_EQ(segments_of(domain), 1) << "joining removed the dead run's topic";
  auto history = core.subscribe<std::uint64_t>("old", {.history = 10}).subscribe().read_all();
  EXPECT_TRUE(history.empty()) << "the topic starts afresh";
}

TEST(ShmProcesses, TheRegistryShowsOtherProcessesAndForgetsThemWhenTheyDie) {
  const auto domain = unique_domain("registry");
  shm::Core core{domain, {.participant = "test"}};
  PeerProcess peer{{"leave_segments", domain, "status"}};
  ASSERT_TRUE(peer.says("created"));
  const auto pid = static_cast<std::uint32_t>(peer.pid());
  auto seen = core.registry();
  ASSERT_EQ(seen.participants.size(), 2u);
  EXPECT_TRUE(seen.participants[0].pid == pid || seen.participants[1].pid == pid);
  EXPECT_TRUE(seen.participants[0].alive && seen.participants[1].alive);
  ASSERT_EQ(seen.topics.size(), 1u);
  EXPECT_EQ(seen.topics[0].publisher_pid, pid);
  EXPECT_EQ(seen.topics[0].publisher, "peer-leave_segments");

  peer.kill9();
  auto after = core.registry();
  for (const auto& p : after.participants) EXPECT_EQ(p.alive, p.name == "test") << p.name;
  EXPECT_EQ(after.topics.at(0).publisher_pid, 0u) << "a dead publisher is not listed";
  core.reclaim();
  ASSERT_EQ(core.registry().participants.size(), 1u) << "reclaiming forgets the dead";
  EXPECT_EQ(core.registry().participants[0].name, "test");
}

}  // namespace
}  // namespace prime::test
