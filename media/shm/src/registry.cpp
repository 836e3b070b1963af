// A participant's membership of an Shm domain: the registry segment's table
// of participants, topics, services and loops, and the leases that say who
// lives.
#include "prime/shm/detail/registry.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <cstring>

#include "prime/common/fixed_text.hpp"
#include "prime/shm/detail/file_lock.hpp"

namespace prime::shm::detail {

namespace {

std::size_t slot_of(ParticipantId id) { return static_cast<std::size_t>(id & ((1u << kSlotBits) - 1)) - 1; }
off_t lease_byte(std::size_t slot) { return static_cast<off_t>(1 + slot); }

template <std::size_t N>
void copy_name(char (&to)[N], const std::string& from) {
  const auto n = std::min(from.size(), N - 1);
  std::memcpy(to, from.data(), n);
  to[n] = '\0';
}

}  // namespace

std::uint64_t own_pid_namespace() {
  struct stat st {};
  return ::stat("/proc/self/ns/pid", &st) == 0 ? static_cast<std::uint64_t>(st.st_ino) : 0;
}

// The table lock: one thread of this process (the mutex) and one
// participant of the domain (the lock on byte 0) at a time.
class Registry::Locked {
 public:
  explicit Locked(const Registry& r) : r_{r}, guard_{r.mutex_} {
    lock_byte(r_.segment_.fd(), 0, "shm domain '" + r_.domain_ + "' registry");
  }
  ~Locked() { unlock_byte(r_.segment_.fd(), 0); }
  Locked(const Locked&) = delete;
  Locked& operator=(const Locked&) = delete;

 private:
  const Registry& r_;
  std::scoped_lock<std::mutex> guard_;
};

std::shared_ptr<Registry> Registry::join(const std::string& domain, const Access& access, const std::string& name,
                                         bool only_if_alive) {
  if (domain.empty()) throw Failure{{Errc::invalid_argument, "shm: a domain needs a name"}};
  // Its registry's name must read back as the domain (tools find domains
  // by it): one shortened with a hash could not.
  if (const auto name = segment_name(domain, "registry", ""); name.find('#') != std::string::npos)
    throw Failure{{Errc::invalid_argument, "shm domain '" + domain.substr(0, 40) + "...': too long (" +
                                             std::to_string(domain.size()) +
                                             " characters; escaped, its registry's name must stay within 200)"}};
  if ((access.permissions & ~0666u) != 0)
    throw Failure{{Errc::invalid_argument, "shm domain '" + domain + "': permissions are read and write bits (at most 0666)"}};
  while (true) {
    auto registry = std::shared_ptr<Registry>{new Registry{domain, access}};
    if (registry->enter(name, only_if_alive)) return registry;
  }
}

std::shared_ptr<Registry> Registry::watch(const std::string& domain, uid_t owner) {
  auto segment = Segment::open_existing(segment_name(domain, "registry", ""), Access{.permissions = 07777, .owner = owner});
  if (!segment || segment->size() < sizeof(RegistryLayout)) return nullptr;
  const auto* r = std::launder(reinterpret_cast<const RegistryLayout*>(segment->data()));
  if (r->magic.load(std::memory_order_acquire) != kRegistryMagic) return nullptr;
  struct stat st {};
  const unsigned mode = ::fstat(segment->fd(), &st) == 0 ? st.st_mode & 0666 : 0600;
  return std::shared_ptr<Registry>{new Registry{domain, {.permissions = mode, .owner = owner}, std::move(*segment)}};
}

Registry::~Registry() { leave(); }

bool Registry::alive(ParticipantId id) const {
  if (id == 0 || (id & kReclaimingBit) != 0) return false;
  if (id == me_) return true;
  const auto slot = slot_of(id);
  if (slot >= kMaxParticipants || layout().participants[slot].id.load() != id) return false;
  return locked_by_other(segment_.fd(), lease_byte(slot));
}

bool Registry::take_to_clear(std::atomic<ParticipantId>& owner) const {
  auto id = owner.load();
  if (me_ == 0 || id == 0 || alive(id & ~kReclaimingBit)) return false;
  return owner.compare_exchange_strong(id, kReclaimingBit | me_);
}

std::string Registry::describe(ParticipantId id) const {
  const auto slot = slot_of(id);
  if (id == 0 || (id & kReclaimingBit) != 0 || slot >= kMaxParticipants) return "no participant";
  const auto& p = layout().participants[slot];
  if (p.id.load() != id) return "a participant that left";
  std::string text = "participant '" + read_text(p.name) + "' (pid " + std::to_string(p.pid);
  if (p.pid_namespace != pid_namespace_) text += " in another pid namespace";
  return text + ")";
}

std::uint32_t Registry::pid_of(ParticipantId id) const {
  const auto slot = slot_of(id);
  if (slot >= kMaxParticipants) return 0;
  const auto& p = layout().participants[slot];
  return p.id.load() == id ? p.pid : 0;
}

std::string Registry::name_of(ParticipantId id) const {
  const auto slot = slot_of(id);
  if (slot >= kMaxParticipants) return {};
  const auto& p = layout().participants[slot];
  return p.id.load() == id ? read_text(p.name) : std::string{};
}

std::size_t Registry::add(EndpointKind kind, const std::string& name) {
  const auto what = std::string{kind_name(kind)} + " '" + name + "'";
  if (name.empty()) throw Failure{{Errc::invalid_argument, "shm: a " + std::string{kind_name(kind)} + " needs a name"}};
  if (name.size() >= kNameCapacity)
    throw Failure{{Errc::invalid_argument, what + ": names are at most " + std::to_string(kNameCapacity - 1) + " characters"}};
  // The table keeps names as text ending in a NUL: one holding a NUL or
  // another control character would never be found again, and take a
  // new entry on every open.
  if (std::any_of(name.begin(), name.end(), [](char c) { return static_cast<unsigned char>(c) < 0x20 || c == 0x7f; }))
    throw Failure{{Errc::invalid_argument, std::string{kind_name(kind)} + " names hold no control character (a NUL, a newline...)"}};
  Locked lock{*this};
  auto& r = layout();
  std::size_t free = kMaxEndpoints;
  for (std::size_t i = 0; i < kMaxEndpoints; ++i) {
    auto& e = r.endpoints[i];
    if (e.used && e.kind == kind && name == read_text(e.name)) return i;
    if (!e.used && free == kMaxEndpoints) free = i;
  }
  if (free == kMaxEndpoints)
    throw Failure{{Errc::domain_full, "shm domain '" + domain_ + "' has its maximum of " + std::to_string(kMaxEndpoints) +
                                          " topics and services"}};
  auto& e = r.endpoints[free];
  e.kind = kind;
  copy_name(e.name, name);
  e.used = 1;
  return free;
}

std::vector<std::string> Registry::names(EndpointKind kind) {
  Locked lock{*this};
  std::vector<std::string> names;
  for (auto& e : layout().endpoints)
    if (e.used && e.kind == kind) names.emplace_back(read_text(e.name));
  return names;
}

std::optional<std::string> Registry::name_at(std::size_t index, EndpointKind kind) {
  if (index >= kMaxEndpoints) return std::nullopt;
  Locked lock{*this};
  const auto& e = layout().endpoints[index];
  if (!e.used || e.kind != kind) return std::nullopt;
  return read_text(e.name);
}

std::vector<RegistrySnapshot::Participant> Registry::participants() {
  Locked lock{*this};
  std::vector<RegistrySnapshot::Participant> list;
  for (auto& p : layout().participants) {
    const auto id = p.id.load();
    if (id != 0) list.push_back({read_text(p.name), p.pid, p.pid_namespace, alive(id)});
  }
  return list;
}

std::size_t Registry::add_loop(const std::string& name, Clock::duration period, Clock::duration deadline) {
  Locked lock{*this};
  auto& r = layout();
  for (std::size_t i = 0; i < kMaxLoops; ++i) {
    auto& l = r.loops[i];
    if (const auto owner = l.owner.load(); owner != 0 && alive(owner)) continue;
    // Each of its pages written here, by the process whose thread will
    // record: the loop's ticks then take no page fault.
    std::destroy_at(&l.record);
    ::new (&l.record) prime::detail::LoopRecord{};
    copy_name(l.name, name);
    l.period_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(period).count();
    l.deadline_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(deadline).count();
    l.owner.store(me_);
    return i;
  }
  throw Failure{{Errc::domain_full, "shm domain '" + domain_ + "' has its maximum of " + std::to_string(kMaxLoops) +
                                        " loops shown to tools (loop '" + name + "')"}};
}

void Registry::remove_loop(std::size_t index) noexcept {
  try {
    Locked lock{*this};
    auto owner = me_;
    layout().loops[index].owner.compare_exchange_strong(owner, 0);
  } catch (...) {
    // The entry stays until this participant is gone: then it is free.
  }
}

std::vector<RegistrySnapshot::Loop> Registry::loops() {
  Locked lock{*this};
  std::vector<RegistrySnapshot::Loop> list;
  for (const auto& l : layout().loops) {
    const auto owner = l.owner.load();
    if (owner == 0 || !alive(owner)) continue;
    list.push_back({read_text(l.name), name_of(owner), pid_of(owner), std::chrono::nanoseconds{l.period_ns},
                    std::chrono::nanoseconds{l.deadline_ns}, prime::detail::stats_of(l.record)});
  }
  return list;
}

std::vector<Registry::Removal> Registry::remove_if_dead() {
  Locked lock{*this};
  auto& r = layout();
  if (std::any_of(std::begin(r.participants), std::end(r.participants), [this](const auto& p) { return alive(p.id.load()); }))
    return {};
  std::vector<Removal> removed;
  bool all_gone = true;
  for (auto& e : r.endpoints) {
    if (!e.used) continue;
    auto name = segment_name(domain_, kind_name(e.kind), read_text(e.name));
    const int error = forget(e);
    all_gone = all_gone && error == 0;
    removed.push_back({std::move(name), error == 0 ? std::string{} : std::strerror(error)});
  }
  if (!all_gone) {
    removed.push_back({segment_.name(), "kept: it lists the segments that stay"});
    return removed;
  }
  const int error = remove_registry();
  removed.push_back({segment_.name(), error == 0 ? std::string{} : std::strerror(error)});
  return removed;
}

std::size_t Registry::forget_dead_participants() {
  Locked lock{*this};
  std::size_t n = 0;
  for (auto& p : layout().participants) {
    auto id = p.id.load();
    if (id != 0 && !alive(id) && p.id.compare_exchange_strong(id, 0)) ++n;
  }
  return n;
}

Registry::Registry(std::string domain, const Access& access)
    : domain_{std::move(domain)},
      access_{access},
      pid_namespace_{own_pid_namespace()},
      segment_{Segment::open(
          segment_name(domain_, "registry", ""), access_, sizeof(RegistryLayout), "shm domain '" + domain_ + "'",
          [this](std::byte* data, std::size_t size) { return is_set_up(data, size); },
          [](std::byte* data, std::size_t) {
            auto* r = ::new (data) RegistryLayout{};
            r->magic.store(kRegistryMagic, std::memory_order_release);
          })} {}

Registry::Registry(std::string domain, const Access& access, Segment segment)
    : domain_{std::move(domain)}, access_{access}, pid_namespace_{own_pid_namespace()}, segment_{std::move(segment)} {}

bool Registry::is_set_up(std::byte* data, std::size_t size) const {
  if (size < sizeof(std::uint64_t)) return false;
  const auto magic = std::launder(reinterpret_cast<RegistryLayout*>(data))->magic.load(std::memory_order_acquire);
  if (magic == 0) return false;
  if (magic != kRegistryMagic || size < sizeof(RegistryLayout))
    throw Failure{{Errc::type_mismatch, "shm domain '" + domain_ + "': its registry was made by another version of Prime"}};
  return true;
}

bool Registry::enter(const std::string& name, bool only_if_alive) {
  Locked lock{*this};
  auto& r = layout();
  // Removed meanwhile (its last participant left): a registry no other
  // participant could find, whatever its magic says.
  if (r.magic.load() != kRegistryMagic || !segment_.linked()) return false;
  const bool anyone_alive = std::any_of(std::begin(r.participants), std::end(r.participants),
                                        [this](const auto& p) { return alive(p.id.load()); });
  if (!anyone_alive && only_if_alive) {
    if (r.generation.load() == 0) remove_registry();  // made by this join just now: nobody's, so it goes again
    throw Failure{{Errc::not_found, "shm domain '" + domain_ +
                                        "' has no live participant (every process in it has exited); what they "
                                        "left stays as it is: 'prime ls' shows it, 'prime clean' removes it"}};
  }
  if (!anyone_alive) {  // an earlier run died: start the domain afresh
    for (auto& e : r.endpoints) forget(e);
    for (auto& p : r.participants) p.id.store(0);
  }
  for (std::size_t i = 0; i < kMaxParticipants; ++i) {
    if (!try_lock_byte(segment_.fd(), lease_byte(i))) continue;  // a live participant's
    auto& p = r.participants[i];
    me_ = ((r.generation.fetch_add(1) + 1) << kSlotBits) | (i + 1);
    pid_ = ::getpid();
    p.pid = static_cast<std::uint32_t>(pid_);
    p.pid_namespace = pid_namespace_;
    copy_name(p.name, name);
    p.id.store(me_);
    return true;
  }
  throw Failure{{Errc::domain_full, "shm domain '" + domain_ + "' has its maximum of " +
                                        std::to_string(kMaxParticipants) + " participants"}};
}

// Not in a child forked after joining: it shares this participant's lease
// (the lock belongs to the open file description both have), and unlocking
// it there would have the parent, alive, taken for dead and its slots
// cleared under it.
void Registry::leave() noexcept {
  if (me_ == 0 || ::getpid() != pid_) return;
  try {
    Locked lock{*this};
    auto& r = layout();
    const auto slot = slot_of(me_);
    r.participants[slot].id.store(0);
    unlock_byte(segment_.fd(), lease_byte(slot));
    me_ = 0;
    const bool anyone_alive = std::any_of(std::begin(r.participants), std::end(r.participants),
                                          [this](const auto& p) { return alive(p.id.load()); });
    if (!anyone_alive) {
      bool all_gone = true;
      for (auto& e : r.endpoints) all_gone = forget(e) == 0 && all_gone;
      if (all_gone) remove_registry();  // else it lists what stays, for a clean
    }
  } catch (...) {
    // The lease goes with the descriptor: others see this participant gone.
  }
}

// Its name first, then its magic, so a participant killed between the two
// leaves nothing behind, not a registry no tool sees; one that opened it
// before the removal finds the name gone, or the magic (enter).
int Registry::remove_registry() {
  const int error = Segment::remove(segment_.name());
  layout().magic.store(0);
  return error;
}

int Registry::forget(RegistryLayout::Endpoint& e) {
  if (!e.used) return 0;
  const int error = Segment::remove(segment_name(domain_, kind_name(e.kind), read_text(e.name)));
  if (error != 0) return error;
  e.used = 0;
  e.name[0] = '\0';
  return 0;
}

}  // namespace prime::shm::detail
