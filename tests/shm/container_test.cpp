// Shm as containers use it: participants in other pid namespaces sharing
// /dev/shm, and a /dev/shm too small for what a topic asks. Each test runs
// its peer under unshare(1) and is skipped, saying why, where that is refused.
#include <gtest/gtest.h>
#include <sys/stat.h>

#include <chrono>
#include <cstdint>
#include <string>
#include <vector>

#include "prime/shm.hpp"
#include "prime/shm/detail/registry.hpp"
#include "shm/domain.hpp"
#include "shm/mapped_topic.hpp"
#include "shm/messages.hpp"
#include "shm/peer_process.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

// Whether `unshare <flags> true` runs here (it needs root, or user namespaces).
bool can_unshare(std::vector<std::string> command) {
  command.insert(command.begin(), "unshare");
  try {
    auto probe = PeerProcess::command(std::move(command));
    return probe.exit_code(10s) == 0;
  } catch (const std::exception&) {
    return false;
  }
}

ino_t inode_of_topic(const std::string& domain, const std::string& topic) {
  struct stat st {};
  const auto path = "/dev/shm/" + shm::detail::segment_name(domain, "topic", topic);
  return ::stat(path.c_str(), &st) == 0 ? st.st_ino : 0;
}

std::optional<shm::RegistrySnapshot::Participant> participant(shm::Core& core, const std::string& name) {
  for (const auto& p : core.registry().participants)
    if (p.name == name) return p;
  return std::nullopt;
}

const std::vector<std::string> kNewPidNamespace{"unshare", "--pid", "--fork", "--mount-proc", "--kill-child"};

TEST(ShmContainers, AJoinerInAnotherPidNamespaceLeavesALiveDomainAloneAndIsSeenDyingThere) {
  if (!can_unshare({"--pid", "--fork", "--mount-proc", "true"}))
    GTEST_SKIP() << "unshare --pid is refused on this machine (it needs root or user namespaces)";
  const auto domain = unique_domain("pidns");
  shm::Core core{domain, {.participant = "host"}};
  auto publisher = core.publisher<std::uint64_t>("alive");
  ASSERT_TRUE(publisher.publish(0));
  const auto inode = inode_of_topic(domain, "alive");
  ASSERT_NE(inode, 0u);

  auto command = kNewPidNamespace;
  command.insert(command.end(), {SHM_PEER_PATH, "receive", domain, "alive", "100"});
  auto joiner = PeerProcess::command(command);
  ASSERT_TRUE(joiner.says("subscribed"));
  EXPECT_EQ(inode_of_topic(domain, "alive"), inode) << "the joiner left the live domain's topic where it was";
  const auto seen = participant(core, "peer-receive");
  ASSERT_TRUE(seen);
  EXPECT_TRUE(seen->alive);
  EXPECT_NE(seen->pid_namespace, shm::detail::own_pid_namespace()) << "it joined from another pid namespace";

  bool received = false;
  const auto give_up = Clock::now() + 30s;
  for (std::uint64_t i = 1; !received && Clock::now() < give_up; ++i) {
    ASSERT_TRUE(publisher.publish(i));
    received = joiner.says("received", 1ms);
  }
  EXPECT_TRUE(received) << "the joiner reads what the host publishes: one topic, not two";
  EXPECT_TRUE(participant(core, "host")->alive) << "the joiner judged the host alive";

  joiner.kill9();  // unshare dies; --kill-child takes the peer inside its namespace with it
  EXPECT_TRUE(MappedTopic::within(10s, [&] {
    const auto p = participant(core, "peer-receive");
    return !p || !p->alive;
  }))
      << "a participant killed in another pid namespace is seen dead from this one";
  EXPECT_EQ(core.reclaim(), 1u) << "its subscriber slot is reclaimed";
}

TEST(ShmContainers, ATopicTooBigForASmallDevShmIsAnErrorAtCreationNotASignalLater) {
  const std::string mount = "mount -t tmpfs -o size=64m tmpfs /dev/shm";
  if (!can_unshare({"--mount", "--propagation", "private", "sh", "-c", mount}))
    GTEST_SKIP() << "unshare --mount (and mounting a tmpfs) is refused on this machine";
  const auto domain = unique_domain("small-shm");
  // A private mount namespace whose /dev/shm is 64 MiB: Docker's default.
  auto peer = PeerProcess::command({"unshare", "--mount", "--propagation", "private", "sh", "-c",
                                    mount + " && exec \"$0\" memory \"$1\"", SHM_PEER_PATH, domain});
  const auto refused = peer.line_starting("refused");
  ASSERT_TRUE(refused) << "creating a 130 MiB topic in 64 MiB must fail at once";
  EXPECT_NE(refused->find("refused no space: topic 'huge': needs " + std::to_string(shm::topic_memory<Image>({})) +
                          " bytes of shared memory, but /dev/shm has "),
            std::string::npos)
      << *refused;
  EXPECT_NE(refused->find(" bytes free"), std::string::npos) << *refused;
  EXPECT_TRUE(peer.says("published 700")) << "a topic that fits works, page after page";
  EXPECT_EQ(peer.exit_code(), 0) << "no SIGBUS";
}

}  // namespace
}  // namespace prime::test
