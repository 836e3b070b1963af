#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <expected>
#include <functional>
#include <memory>
#include <mutex>
#include <string>
#include <vector>

#include "prime/common/fingerprint.hpp"
#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/shm/service_handles.hpp"
#include "prime/shm/detail/service.hpp"

namespace prime::shm::detail {

// One client handle's hold on one service: the service's segment and a
// client slot in it, taken when first needed and taken again when the
// service comes back (a restarted server, or one that made its segment
// anew). Copies of a chain handle share it; it leaves its slot when the
// last goes.
//
// Thread-safe.
class Binding {
 public:
  Binding(std::shared_ptr<Registry> registry, std::string name, Fingerprint request, Fingerprint reply, ClientQos qos)
      : registry_{std::move(registry)}, name_{std::move(name)}, request_{request}, reply_{reply}, qos_{qos} {}
  Binding(const Binding&) = delete;
  Binding& operator=(const Binding&) = delete;
  ~Binding();

  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  [[nodiscard]] const ClientQos& qos() const noexcept { return qos_; }
  [[nodiscard]] const Fingerprint& request() const noexcept { return request_; }
  [[nodiscard]] const Fingerprint& reply() const noexcept { return reply_; }

  // The service with a live server and this client's slot in it, waiting
  // for one up to ClientQos::wait_for_service; or why not.
  std::expected<std::shared_ptr<Service>, Error> ready(Clock::time_point now);

  // Claims a cell of this client's in `service` for one call, checking the
  // service's limits; its ticket is in the cell's status.
  std::expected<std::size_t, Error> claim(Service& service, Clock::time_point at);

 private:
  // The service, bound (its segment open, a client slot taken) and its
  // server seen alive; the fast path trusts the last look for 1 ms.
  std::expected<std::shared_ptr<Service>, Error> bind(Clock::time_point now);
  bool live(const Service& service) const { return registry_->alive(service.header().server.load()); }
  std::expected<void, Error> take_slot(Service& service);
  // Gives the slot up, and its cells; with `keep_posts` (the last handle
  // went: no call of this client runs) not those of posts under way: a post
  // is sent once post() returns, and its workers free its cells.
  void release_slot(bool keep_posts = false);
  void unbind();

  std::shared_ptr<Registry> registry_;
  std::string name_;
  Fingerprint request_;
  Fingerprint reply_;
  ClientQos qos_;
  std::mutex mutex_;
  std::shared_ptr<Service> service_;
  std::size_t slot_ = 0;
  ParticipantId checked_server_ = 0;  // the server last seen alive, and until when that is trusted
  Clock::time_point checked_until_{};
};

}  // namespace prime::shm::detail
