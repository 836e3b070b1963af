// Shm domains seen from outside, for tools: listed, inspected and cleaned.
#include "prime/shm/inspect.hpp"

#include <sys/stat.h>

#include <algorithm>
#include <filesystem>

#include "prime/logic/error.hpp"
#include "prime/shm/detail/registry.hpp"
#include "prime/shm/detail/segment.hpp"
#include "prime/shm/detail/snapshot.hpp"

namespace prime::shm {

std::optional<RegistrySnapshot> inspect(const std::string& domain, uid_t owner) {
  auto registry = detail::Registry::watch(domain, owner);
  if (!registry) return std::nullopt;
  return detail::snapshot(registry);
}

std::optional<DomainAccess> access_of(const std::string& domain) {
  struct stat st {};
  const auto path = std::string{detail::kShmDirectory} + "/" + detail::segment_name(domain, "registry", "");
  if (::lstat(path.c_str(), &st) != 0) return std::nullopt;
  return DomainAccess{.owner = st.st_uid, .permissions = static_cast<unsigned>(st.st_mode & 07777)};
}

std::vector<DomainSummary> domains() {
  std::vector<DomainSummary> found;
  std::error_code ignored;
  for (const auto& entry : std::filesystem::directory_iterator{detail::kShmDirectory, ignored}) {
    const auto file = entry.path().filename().string();
    const std::string suffix = ".registry.";
    if (!file.starts_with("prime.") || !file.ends_with(suffix)) continue;
    const auto domain = detail::unescape(file.substr(6, file.size() - 6 - suffix.size()));
    std::optional<RegistrySnapshot> snapshot;
    try {
      snapshot = inspect(domain);
    } catch (const Failure& f) {
      found.push_back({.name = domain, .unreadable = f.error().message});
      continue;
    }
    if (!snapshot) continue;
    DomainSummary d{.name = domain};
    for (const auto& p : snapshot->participants) (p.alive ? d.participants_alive : d.participants_dead) += 1;
    d.topics = snapshot->topics.size();
    d.services = snapshot->services.size();
    found.push_back(std::move(d));
  }
  std::sort(found.begin(), found.end(), [](const auto& a, const auto& b) { return a.name < b.name; });
  return found;
}

std::vector<std::string> clean(const std::string& domain) {
  auto registry = detail::Registry::watch(domain);
  if (!registry) return {};
  std::vector<std::string> done;
  for (const auto& [name, why] : registry->remove_if_dead())
    done.push_back(why.empty() ? "removed /dev/shm/" + name : "could not remove /dev/shm/" + name + ": " + why);
  if (!done.empty()) return done;
  const auto before = registry->participants();
  // Slots are cleared by a participant, whose lease tells the others it is
  // at work: this tool joins the domain while it clears them.
  std::shared_ptr<detail::Registry> member;
  try {
    member = detail::Registry::join(domain, registry->access(), "prime clean", true);
  } catch (const Failure& f) {
    if (f.error().code == Errc::not_found) return clean(domain);  // its last process exited meanwhile
    throw;
  }
  const auto freed = detail::reclaim(member);
  for (const auto& p : before)
    if (!p.alive) done.push_back("forgot dead participant '" + p.name + "' (pid " + std::to_string(p.pid) + ")");
  if (freed > 0) done.push_back("freed " + std::to_string(freed) + " subscriber and client slots of dead participants");
  return done;
}

}  // namespace prime::shm
