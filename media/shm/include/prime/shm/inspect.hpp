#pragma once

#include <sys/types.h>
#include <unistd.h>

#include <cstddef>
#include <optional>
#include <string>
#include <vector>

#include "prime/shm/registry.hpp"

namespace prime::shm {

// Looking at shared-memory domains from outside, for tools: nothing here
// joins a domain, takes a slot or makes anyone wait.

// A domain on this machine and how alive it is.
struct DomainSummary {
  std::string name;
  std::size_t participants_alive = 0;
  std::size_t participants_dead = 0;  // listed, but their lease is gone
  std::size_t topics = 0;
  std::size_t services = 0;
  std::string unreadable{};  // why it could not be looked at (another user's, say); the counts are then 0
};

// What domain `domain` holds now, or nothing when it does not exist. Its
// registry is read only when `owner` (this user by default) made it.
[[nodiscard]] std::optional<RegistrySnapshot> inspect(const std::string& domain, uid_t owner = ::geteuid());

// Who set domain `domain` up and whom its segments admit: the owner and
// permission bits of its registry, or nothing when it does not exist. A
// tool joins a running domain with these (DomainOptions::owner and
// permissions), so a group's 0660 domain is joined as its participants do,
// once the tool has decided to trust that owner.
struct DomainAccess {
  uid_t owner = 0;
  unsigned permissions = 0;
};
[[nodiscard]] std::optional<DomainAccess> access_of(const std::string& domain);

// The domains whose registry lies in /dev/shm, alive or dead; one this
// process may not read is listed with the reason.
[[nodiscard]] std::vector<DomainSummary> domains();

// What dead participants left in `domain`: of a domain no one lives in,
// every segment (removed); of a live one, their registry entries and slots
// (freed: nothing of a live participant is touched). Says what it did, a
// line each ("removed <path>"; "could not remove <path>: <why>" for a
// segment that stayed); nothing when there was nothing to do.
std::vector<std::string> clean(const std::string& domain);

}  // namespace prime::shm
