#pragma once

#include <cstddef>
#include <memory>
#include <string>

#include "prime/common/fixed_text.hpp"
#include "prime/shm/detail/registry.hpp"
#include "prime/shm/detail/service.hpp"
#include "prime/shm/detail/topic.hpp"
#include "prime/shm/registry.hpp"

namespace prime::shm::detail {

// Topic or service `name` to look at, or null: a damaged one is passed
// over (the rest of the domain is still shown), as one that is gone.
inline std::shared_ptr<Topic> inspect_or_skip(const std::shared_ptr<Registry>& registry, const std::string& name) {
  try {
    return Topic::inspect(registry, name);
  } catch (const Failure&) {
    return nullptr;
  }
}
inline std::shared_ptr<Service> open_or_skip(const std::shared_ptr<Registry>& registry, const std::string& name) {
  try {
    return Service::open_existing(registry, name);
  } catch (const Failure&) {
    return nullptr;
  }
}

// What `registry`'s domain holds now: its participants, topics, services
// and loops.
inline RegistrySnapshot snapshot(const std::shared_ptr<Registry>& registry) {
  RegistrySnapshot s;
  s.participants = registry->participants();
  for (const auto& name : registry->topics()) {
    auto topic = inspect_or_skip(registry, name);
    if (!topic) continue;
    auto& h = topic->header();
    RegistrySnapshot::Topic t{name, h.type.describe(), topic->qos(), 0, {}, {}, h.head.load(), read_text(h.schema), h.type};
    if (const auto publisher = h.publisher.load(); registry->alive(publisher)) {
      t.publisher_pid = registry->pid_of(publisher);
      t.publisher = registry->name_of(publisher);
    }
    for (std::size_t i = 0; i < topic->geometry().max_subscribers; ++i)
      if (const auto owner = h.subscribers[i].owner.load(); registry->alive(owner))
        t.subscriber_pids.push_back(registry->pid_of(owner));
    s.topics.push_back(std::move(t));
  }
  for (const auto& name : registry->names(EndpointKind::service)) {
    auto service = open_or_skip(registry, name);
    if (!service) continue;
    auto& h = service->header();
    RegistrySnapshot::Service v{name, h.request_type.describe(), h.reply_type.describe(), service->qos(), 0, {}, {},
                                h.served.load(), h.failed.load(), h.requests_in.load(), h.forwarded_in.load(),
                                h.replies_out.load(), h.forwarded_out.load(), read_text(h.request_schema),
                                read_text(h.reply_schema)};
    if (const auto server = h.server.load(); registry->alive(server)) {
      v.server_pid = registry->pid_of(server);
      v.server = registry->name_of(server);
    }
    for (std::size_t c = 0; c < service->geometry().max_clients; ++c)
      if (const auto owner = h.clients[c].owner.load(); registry->alive(owner))
        v.client_pids.push_back(registry->pid_of(owner));
    s.services.push_back(std::move(v));
  }
  s.loops = registry->loops();
  return s;
}

// Frees what dead participants left in `registry`'s domain; returns the
// subscriber and client slots freed.
inline std::size_t reclaim(const std::shared_ptr<Registry>& registry) {
  registry->forget_dead_participants();
  std::size_t freed = 0;
  for (const auto& name : registry->topics())
    if (auto topic = inspect_or_skip(registry, name)) freed += topic->reclaim_dead_subscribers();
  for (const auto& name : registry->names(EndpointKind::service))
    if (auto service = open_or_skip(registry, name)) freed += service->reclaim_dead_clients();
  return freed;
}

}  // namespace prime::shm::detail
