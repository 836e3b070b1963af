#pragma once

#include <algorithm>
#include <atomic>
#include <chrono>
#include <cstdint>
#include <cstring>
#include <fstream>
#include <new>
#include <optional>
#include <string>
#include <thread>
#include <vector>

#include "prime/common/fingerprint.hpp"
#include "prime/logic/error.hpp"
#include "prime/shm/detail/process.hpp"
#include "prime/shm/detail/segment.hpp"
#include "prime/shm/detail/topic.hpp"
#include "prime/shm/qos.hpp"

namespace prime::shm {

// What the registry shows of a domain at one moment.
struct RegistrySnapshot {
  struct Participant {
    std::string name;
    std::uint32_t pid;
  };
  struct Topic {
    std::string name;
    std::string type;  // Fingerprint::describe()
    TopicQos qos;
    std::uint32_t publisher_pid;  // 0: none
    std::vector<std::uint32_t> subscriber_pids;
    std::uint64_t published;  // sequences so far
  };
  std::vector<Participant> participants;
  std::vector<Topic> topics;
};

namespace detail {

inline constexpr std::uint64_t kRegistryMagic = 0x5052494d45524731ull;  // "PRIMERG1"
inline constexpr std::size_t kMaxParticipants = 128;
inline constexpr std::size_t kMaxTopics = 512;

struct RegistryLayout {
  struct Participant {
    std::atomic<ProcessId> id{0};
    char name[56]{};
  };
  struct TopicEntry {
    std::uint32_t used = 0;
    char name[244]{};
  };
  std::atomic<std::uint64_t> magic{0};
  std::atomic<ProcessId> lock{0};
  Participant participants[kMaxParticipants];
  TopicEntry topics[kMaxTopics];
};

// The domain's table of participants and topics, in its own segment. Changes
// happen under a lock word whose holder, should it die, is replaced; the
// data path never touches it.
//
// Thread-safe.
class Registry {
 public:
  Registry(std::string domain, unsigned permissions) : domain_{std::move(domain)}, permissions_{permissions} {
    segment_ = open_or_create();
  }

  // Joins the domain as `name`. When no participant of an earlier run is
  // alive, that run's segments are removed first.
  void join(const std::string& name) {
    Locked lock{*this};
    auto& r = layout();
    const bool anyone_alive = std::any_of(std::begin(r.participants), std::end(r.participants),
                                          [](const auto& p) { return alive(p.id.load()); });
    if (!anyone_alive) {
      for (auto& t : r.topics) forget(t);
    }
    reclaim_locked();
    for (std::size_t i = 0; i < kMaxParticipants; ++i) {
      ProcessId free = 0;
      if (r.participants[i].id.compare_exchange_strong(free, me_)) {
        copy_name(r.participants[i].name, name);
        slot_ = i;
        return;
      }
    }
    throw Failure{{Errc::limit_exceeded, "shm domain '" + domain_ + "' has its maximum of " +
                                             std::to_string(kMaxParticipants) + " participants"}};
  }

  // Leaves the domain; the last to leave removes every segment of it.
  void leave() {
    Locked lock{*this};
    auto& r = layout();
    if (slot_ < kMaxParticipants) r.participants[slot_].id.store(0);  // this core's entry: a process may have several
    const bool anyone_alive = std::any_of(std::begin(r.participants), std::end(r.participants),
                                          [](const auto& p) { return alive(p.id.load()); });
    if (!anyone_alive) {
      for (auto& t : r.topics) forget(t);
      r.magic.store(0);
      Segment::remove(segment_->name());
    }
  }

  void add_topic(const std::string& name) {
    Locked lock{*this};
    auto& r = layout();
    TopicEntry* free = nullptr;
    for (auto& t : r.topics) {
      if (t.used && name == t.name) return;
      if (!t.used && !free) free = &t;
    }
    if (!free)
      throw Failure{{Errc::limit_exceeded, "shm domain '" + domain_ + "' has its maximum of " +
                                               std::to_string(kMaxTopics) + " topics"}};
    if (name.size() >= sizeof free->name)
      throw Failure{{Errc::limit_exceeded, "topic '" + name + "': names are at most " +
                                               std::to_string(sizeof free->name - 1) + " characters"}};
    copy_name(free->name, name);
    free->used = 1;
  }

  // Clears what dead participants left: their registry entries, their
  // subscriber slots (and the samples those held). Returns how many
  // subscriber slots were reclaimed.
  std::size_t reclaim() {
    Locked lock{*this};
    return reclaim_locked();
  }

  [[nodiscard]] RegistrySnapshot snapshot() {
    Locked lock{*this};
    RegistrySnapshot s;
    for (auto& p : layout().participants) {
      const auto id = p.id.load();
      if (alive(id)) s.participants.push_back({p.name, pid_of(id)});
    }
    for (auto& t : layout().topics) {
      if (!t.used) continue;
      auto mapped = Topic::inspect(domain_, t.name);
      if (!mapped) continue;
      auto& h = mapped->header();
      RegistrySnapshot::Topic topic{t.name, h.type.describe(), {}, 0, {}, h.head.load()};
      topic.qos = mapped->qos();
      if (const auto pub = h.publisher.load(); alive(pub)) topic.publisher_pid = pid_of(pub);
      for (std::size_t i = 0; i < h.max_subscribers; ++i) {
        const auto owner = h.subscribers[i].owner.load();
        if (owner != kReclaiming && alive(owner)) topic.subscriber_pids.push_back(pid_of(owner));
      }
      s.topics.push_back(std::move(topic));
    }
    return s;
  }

 private:
  using TopicEntry = RegistryLayout::TopicEntry;

  class Locked {
   public:
    explicit Locked(Registry& r) : r_{r} {
      auto& word = r_.layout().lock;
      while (true) {
        ProcessId holder = 0;
        if (word.compare_exchange_weak(holder, r_.me_)) return;
        if (holder != 0 && holder != r_.me_ && !alive(holder)) {
          if (word.compare_exchange_strong(holder, r_.me_)) return;  // its holder died
        }
        std::this_thread::sleep_for(std::chrono::microseconds{100});
      }
    }
    ~Locked() { r_.layout().lock.store(0); }
    Locked(const Locked&) = delete;
    Locked& operator=(const Locked&) = delete;

   private:
    Registry& r_;
  };

  RegistryLayout& layout() const { return *std::launder(reinterpret_cast<RegistryLayout*>(segment_->data())); }

  std::optional<Segment> open_or_create() {
    const auto name = segment_name(domain_, "registry", "");
    auto deadline = std::chrono::steady_clock::now() + std::chrono::seconds{2};
    while (true) {
      if (auto existing = Segment::open(name)) {
        auto* r = std::launder(reinterpret_cast<RegistryLayout*>(existing->data()));
        if (existing->size() >= sizeof(RegistryLayout) && r->magic.load(std::memory_order_acquire) == kRegistryMagic)
          return existing;
      } else if (auto created = Segment::create(name, sizeof(RegistryLayout), permissions_)) {
        auto* r = ::new (created->data()) RegistryLayout{};
        r->magic.store(kRegistryMagic, std::memory_order_release);
        return created;
      }
      if (std::chrono::steady_clock::now() > deadline) {
        Segment::remove(name);  // left half-made by a creator that died, or by a last participant leaving
        deadline = std::chrono::steady_clock::now() + std::chrono::seconds{2};
      }
      std::this_thread::sleep_for(std::chrono::milliseconds{1});
    }
  }

  std::size_t reclaim_locked() {
    auto& r = layout();
    for (auto& p : r.participants) {
      auto id = p.id.load();
      if (id != 0 && !alive(id)) p.id.compare_exchange_strong(id, 0);
    }
    std::size_t reclaimed = 0;
    for (auto& t : r.topics) {
      if (!t.used) continue;
      if (auto mapped = Topic::inspect(domain_, t.name)) reclaimed += mapped->reclaim_dead_subscribers();
    }
    return reclaimed;
  }

  void forget(TopicEntry& t) {
    if (!t.used) return;
    Segment::remove(segment_name(domain_, "topic", t.name));
    t.used = 0;
    t.name[0] = '\0';
  }

  template <std::size_t N>
  static void copy_name(char (&to)[N], const std::string& from) {
    const auto n = std::min(from.size(), N - 1);
    std::memcpy(to, from.data(), n);
    to[n] = '\0';
  }

  std::string domain_;
  unsigned permissions_;
  ProcessId me_ = this_process();
  std::size_t slot_ = kMaxParticipants;  // where this participant is listed, once joined
  std::optional<Segment> segment_;
};

}  // namespace detail
}  // namespace prime::shm
