#pragma once

#include <unistd.h>

#include <atomic>
#include <cstdint>
#include <memory>
#include <mutex>
#include <new>
#include <optional>
#include <string>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/shm/detail/layout.hpp"
#include "prime/shm/detail/segment.hpp"
#include "prime/shm/registry.hpp"
#include "prime/topology/loop.hpp"

namespace prime::shm::detail {

inline constexpr std::size_t kMaxParticipants = 128;
inline constexpr std::size_t kMaxEndpoints = 512;  // topics and services
inline constexpr std::size_t kMaxLoops = 64;

// What a registry entry names, and the kind in its segment's name.
enum class EndpointKind : std::uint32_t { topic = 1, service = 2 };
inline const char* kind_name(EndpointKind kind) { return kind == EndpointKind::topic ? "topic" : "service"; }
inline constexpr std::size_t kNameCapacity = 244;
inline constexpr int kSlotBits = 8;
static_assert(kMaxParticipants < (1u << kSlotBits));

// The registry segment. Its file carries the domain's locks: byte 0 guards
// changes to the table (and setting the segment up); byte 1 + i is the lease
// of participant slot i, held by that participant for as long as it lives.
struct RegistryLayout {
  struct Participant {
    std::atomic<ParticipantId> id{0};
    std::uint32_t pid = 0;
    std::uint64_t pid_namespace = 0;
    char name[48]{};
  };
  struct Endpoint {
    std::uint32_t used = 0;
    EndpointKind kind = EndpointKind::topic;
    char name[kNameCapacity]{};
  };
  // A periodic loop of a participant, and what its thread records there
  // (prime::every): tools read its statistics while it runs.
  struct Loop {
    std::atomic<ParticipantId> owner{0};  // 0: free; a dead owner's may be taken
    char name[48]{};
    std::int64_t period_ns = 0;
    std::int64_t deadline_ns = 0;
    prime::detail::LoopRecord record;
  };
  std::atomic<std::uint64_t> magic{0};
  std::atomic<std::uint64_t> generation{0};  // participant ids handed out so far
  Participant participants[kMaxParticipants];
  Endpoint endpoints[kMaxEndpoints];
  Loop loops[kMaxLoops];
};

// The inode of this process's pid namespace (0 if it cannot be read).
[[nodiscard]] std::uint64_t own_pid_namespace();

// This participant's membership of a domain: its lease in the registry, and
// the registry's table of participants and topics. A participant is alive
// while it holds its lease; the kernel drops the lease when it dies, in any
// pid namespace, so nothing here reads another process's /proc. Topics,
// publishers and subscribers hold this jointly with the Core: the
// participant leaves when the last of them goes, and the last participant
// to leave removes the domain's segments.
//
// Thread-safe.
class Registry : public std::enable_shared_from_this<Registry> {
 public:
  // Joins `domain` as `name`. When no participant of an earlier run is alive,
  // that run's topics are removed first; or, `only_if_alive` (a tool that
  // works on a running system), nothing is touched and joining fails.
  static std::shared_ptr<Registry> join(const std::string& domain, const Access& access, const std::string& name,
                                        bool only_if_alive = false);
  // The registry of `domain` seen from outside, joining nothing (no lease,
  // no slot): for tools. Null when the domain does not exist. Its
  // segments are taken from `owner` alone (this user by default), with the
  // registry's mode.
  static std::shared_ptr<Registry> watch(const std::string& domain, uid_t owner = ::geteuid());
  Registry(const Registry&) = delete;
  Registry& operator=(const Registry&) = delete;
  ~Registry();

  [[nodiscard]] const std::string& domain() const noexcept { return domain_; }
  [[nodiscard]] const Access& access() const noexcept { return access_; }
  [[nodiscard]] ParticipantId me() const noexcept { return me_; }

  // Whether the participant `id` still lives: it is still in its slot, and
  // someone holds that slot's lease. One system call.
  [[nodiscard]] bool alive(ParticipantId id) const;

  // Takes a slot whose owner (the word `owner`) is dead, or died clearing
  // it, for this participant to clear: the word then names this one as
  // clearing it, until the clearer sets it to 0. False when the slot is
  // free, its owner or clearer lives, or another took it first; and for a
  // registry that only watches (no lease: others could not tell it from a
  // dead clearer, and would clear the slot again under it).
  [[nodiscard]] bool take_to_clear(std::atomic<ParticipantId>& owner) const;

  // "participant 'planner' (pid 42)", for errors that name a peer.
  [[nodiscard]] std::string describe(ParticipantId id) const;
  [[nodiscard]] std::uint32_t pid_of(ParticipantId id) const;
  [[nodiscard]] std::string name_of(ParticipantId id) const;

  // Lists `name` among the domain's topics or services; returns its entry's
  // index, which stays its own while the domain lives.
  std::size_t add(EndpointKind kind, const std::string& name);

  // The names of the domain's topics (or services).
  [[nodiscard]] std::vector<std::string> names(EndpointKind kind);
  [[nodiscard]] std::vector<std::string> topics() { return names(EndpointKind::topic); }

  // The name of entry `index`, if it is a `kind`.
  [[nodiscard]] std::optional<std::string> name_at(std::size_t index, EndpointKind kind);

  // The participants, as the table lists them now.
  [[nodiscard]] std::vector<RegistrySnapshot::Participant> participants();

  // Lists a loop of this participant; its statistics are recorded in the
  // entry until `remove_loop(index)`. Takes a free entry, or one whose
  // owner died.
  std::size_t add_loop(const std::string& name, Clock::duration period, Clock::duration deadline);
  // The loop's place for its thread to record, in entry `index`.
  [[nodiscard]] prime::detail::LoopRecord& loop_record(std::size_t index) const { return layout().loops[index].record; }
  void remove_loop(std::size_t index) noexcept;

  // The live participants' loops, with their statistics as of now.
  [[nodiscard]] std::vector<RegistrySnapshot::Loop> loops();

  // A segment removed, or not (`why`: what kept it).
  struct Removal {
    std::string name;
    std::string why{};
  };
  // When no participant of the domain lives: removes every segment of it
  // and says how each went (a dead domain's remains); otherwise nothing.
  // A segment that stays (another user's, say) stays listed, and so does
  // the registry that lists it, for a clean by someone who may remove it.
  std::vector<Removal> remove_if_dead();

  // Forgets participants that died without leaving; returns them.
  std::size_t forget_dead_participants();

 private:
  class Locked;

  Registry(std::string domain, const Access& access);
  Registry(std::string domain, const Access& access, Segment segment);

  bool is_set_up(std::byte* data, std::size_t size) const;
  // Takes a slot and its lease. False when the domain was removed meanwhile
  // (its last participant left): join again.
  bool enter(const std::string& name, bool only_if_alive);
  // Leaves the domain (see the definition for a forked child).
  void leave() noexcept;
  // Removes the registry (its table lock held): its name first, then its
  // magic.
  int remove_registry();
  // Removes entry `e`'s segment and forgets it; 0, or the errno that kept
  // the segment, which then stays listed (never an orphan no clean finds).
  int forget(RegistryLayout::Endpoint& e);

  [[nodiscard]] RegistryLayout& layout() const {
    return *std::launder(reinterpret_cast<RegistryLayout*>(segment_.data()));
  }

  std::string domain_;
  Access access_;
  std::uint64_t pid_namespace_;
  mutable std::mutex mutex_;
  Segment segment_;
  ParticipantId me_ = 0;
  pid_t pid_ = 0;  // the process that joined
};

}  // namespace prime::shm::detail
