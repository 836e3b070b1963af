// A service's server: takes the service over, recovers what a dead one
// left, and its workers answer calls in place (or hand a linked call's
// output to the next service).
#include "prime/shm/detail/server.hpp"

#include <algorithm>
#include <bit>
#include <cstring>
#include <exception>

#include "prime/shm/detail/prefetch.hpp"
#include "prime/topology/detail/wait.hpp"

namespace prime::shm::detail {

Server::Server(std::shared_ptr<Service> service, const ServiceQos& qos, Handler handler, std::function<void(Error)> report)
    : service_{std::move(service)}, spin_{qos.spin}, handler_{std::move(handler)}, report_{std::move(report)} {
  auto& h = service_->header();
  auto& registry = service_->registry();
  auto current = h.server.load();
  while (true) {
    if (current != 0 && registry.alive(current))
      throw Failure{{Errc::in_use, "service '" + service_->name() + "' is served already by " + registry.describe(current)}};
    if (h.server.compare_exchange_strong(current, registry.me())) break;
  }
  h.workers.store(static_cast<std::uint32_t>(qos.workers));
  h.queue_depth.store(qos.queue_depth);
  h.min_interval_ns.store(saturating_cast<std::chrono::nanoseconds>(qos.min_interval).count());
  h.timeout_ns.store(saturating_cast<std::chrono::nanoseconds>(qos.timeout).count());
  h.requests.forget(~0ull);  // an earlier server's workers may have died asleep
  recover();
}

Server::~Server() {
  auto& h = service_->header();
  auto me = service_->registry().me();
  h.server.compare_exchange_strong(me, 0);
  for (std::size_t i = 0; i < service_->geometry().cell_count(); ++i) service_->tail(i).answered.ring();  // callers see it gone
}

void Server::work(std::size_t index, const std::stop_token& stop) {
  auto& h = service_->header();
  std::stop_callback wake{stop, [&h] { h.requests.ring_always(); }};
  std::size_t start = index;  // workers look at the pending bits from different places
  auto ready = [&] {
    for (const auto& word : h.pending)
      if (word.load(std::memory_order_relaxed) != 0) return true;
    return false;
  };
  std::optional<Clock::time_point> next_check;  // read only once the worker sleeps: a busy one reads no clock
  auto sleep = [&](Clock::time_point until) {
    if (!next_check || Clock::now() >= *next_check) {  // idle: a good time to free what dead clients left
      service_->reclaim_dead_clients();
      next_check = Clock::now() + std::chrono::milliseconds{100};
    }
    h.requests.sleep_until(1ull << index, [&] { return ready() || stop.stop_requested(); },
                           std::min(until, *next_check));
  };
  while (true) {
    if (prime::detail::spin_then_sleep(prime::detail::yielding(ready), sleep, spin_, Clock::time_point::max(), stop) !=
        prime::detail::Waited::ready)
      return;
    if (auto cell = take(start)) serve(*cell);
  }
}

std::optional<std::size_t> Server::take(std::size_t& start) {
  auto& h = service_->header();
  for (std::size_t n = 0; n < kPendingWords; ++n) {
    const auto w = (start + n) % kPendingWords;
    auto bits = h.pending[w].load(std::memory_order_acquire);
    while (bits != 0) {
      const auto rotate = static_cast<int>(start % 64);
      const auto pick = (std::rotr(bits, rotate) & -std::rotr(bits, rotate));  // lowest bit from `rotate` on
      const auto bit = std::rotl(pick, rotate);
      const auto cell = w * 64 + static_cast<std::size_t>(std::countr_zero(bit));
      if (!service_->has_cell(cell)) {  // raised by a foreign or broken program: no call is there
        h.pending[w].fetch_and(~bit, std::memory_order_relaxed);
        bits &= ~bit;
        continue;
      }
      // Fetch the cell's status and request while the bit is taken: the
      // transfers overlap instead of following one another.
      prefetch_for_write(&service_->cell(cell).status);
      __builtin_prefetch(service_->request(cell));
      if (h.pending[w].fetch_and(~bit, std::memory_order_acq_rel) & bit) {
        ++start;
        return cell;
      }
      bits &= ~bit;
    }
  }
  return std::nullopt;
}

void Server::serve(std::size_t i) {
  auto& h = service_->header();
  auto& c = service_->cell(i);
  auto s = c.status.load();
  if (Status::state(s) == CellState::abandoned) return service_->free_abandoned(i, Status::ticket(s));
  if (Status::state(s) != CellState::queued) return;  // freed by its caller meanwhile
  const auto ticket = Status::ticket(s);
  if (!c.status.compare_exchange_strong(s, Status::pack(ticket, CellState::running))) return;

  // A linked call's route, read once from the cell. One longer than a
  // call can be (written by a foreign or broken caller) fails the call;
  // a hop to a cell a service does not have, as if its caller gave up.
  const std::uint32_t hops = c.next_hops;
  if (hops >= kMaxHops) {
    h.failed.fetch_add(1);
    const Error damaged{Errc::damaged, "service '" + service_->name() + "': a call's cell is damaged (" +
                                                 std::to_string(hops) + " services after this one, at most " +
                                                 std::to_string(kMaxHops - 1) + ")"};
    return answer(i, ticket, &damaged);
  }
  Hop route[kMaxHops - 1];
  std::copy(service_->tail(i).next, service_->tail(i).next + hops, route);

  // Where the answer goes: this cell, or the next service's cell of a linked call.
  Service* next = nullptr;
  std::byte* out = service_->reply(i);
  std::size_t capacity = service_->geometry().max_reply_size;
  if (hops > 0) {
    next = following(route[0]);
    if (!next || !take_over(*next, route[0])) {  // its caller gave up, or the service is gone
      if (c.posted) free_posted(route, 1, hops);  // no caller frees a post's later cells
      return finish(i, ticket, false);
    }
    out = next->request(route[0].cell);
    capacity = next->geometry().max_request_size;
  }

  std::optional<Error> error;
  std::size_t size = 0;
  try {
    // The next service of a linked call may have come back for other
    // types since the call was linked: its cell is not this reply's.
    if (next && !forwards_into(service_->header().reply_type, next->header().request_type))
      throw Failure{{Errc::type_mismatch, "the next service, '" + next->name() + "', takes " +
                                              next->header().request_type.describe() + ", not this one's reply, " +
                                              service_->header().reply_type.describe()}};
    size = handler_(service_->request(i), service_->request_size(c), out, capacity);
  } catch (const Failure& f) {
    error = f.error();
  } catch (const std::exception& e) {
    error = Error{Errc::block_failed, e.what()};
  } catch (...) {
    error = Error{Errc::block_failed, "an exception of unknown type"};
  }

  if (error) {
    h.failed.fetch_add(1);
    error->message = "service '" + service_->name() + "': " + error->message;
    if (c.posted && report_) report_(*error);
    if (!next) return answer(i, ticket, &*error);
    fail_linked(route, hops, *next, *error, c.posted != 0);
    return finish(i, ticket, false);
  }
  h.served.fetch_add(1);
  if (!next) {
    c.reply_size = size;
    h.replies_out.fetch_add(1);
    return answer(i, ticket, nullptr);
  }
  // Linked: the output already lies in the next service's cell; hand it on.
  const auto hop = route[0];
  auto& to = next->cell(hop.cell);
  to.request_size = size;
  to.stamp = c.stamp;
  to.next_hops = hops - 1;
  std::copy(route + 1, route + hops, next->tail(hop.cell).next);
  auto held = Status::pack(hop.ticket, CellState::forwarding);
  if (to.status.compare_exchange_strong(held, Status::pack(hop.ticket, CellState::queued))) {
    h.forwarded_out.fetch_add(1);
    next->header().forwarded_in.fetch_add(1);
    next->enqueue(hop.cell);
  } else {
    next->free_abandoned(hop.cell, hop.ticket);
  }
  finish(i, ticket, false);
}

bool Server::take_over(Service& next, const Hop& hop) {
  if (!next.has_cell(hop.cell)) return false;
  auto claimed = Status::pack(hop.ticket, CellState::claimed);
  return next.cell(hop.cell).status.compare_exchange_strong(claimed, Status::pack(hop.ticket, CellState::forwarding));
}

void Server::answer(std::size_t i, std::uint64_t ticket, const Error* error) {
  auto& c = service_->cell(i);
  if (c.posted) return finish(i, ticket, true);
  if (error) write_error(c, service_->tail(i), *error);
  auto running = Status::pack(ticket, CellState::running);
  if (c.status.compare_exchange_strong(running, Status::pack(ticket, error ? CellState::failed : CellState::done)))
    service_->tail(i).answered.ring();
  else
    service_->free_abandoned(i, ticket);
}

void Server::finish(std::size_t i, std::uint64_t ticket, bool free) {
  auto& c = service_->cell(i);
  auto running = Status::pack(ticket, CellState::running);
  const auto after = free || c.posted ? Status::pack(ticket + 1, CellState::free) : Status::pack(ticket, CellState::done);
  if (!c.status.compare_exchange_strong(running, after)) service_->free_abandoned(i, ticket);
}

// A linked call failed here, while this worker holds the next cell of its
// `route` (`hops` long), forwarding. A call's caller waits on its last
// cell, so the error goes there and the next cell goes back to the caller
// (claimed), who frees it with the rest. A post's caller waits for nothing
// and frees nothing: every cell of its route is freed here.
void Server::fail_linked(const Hop* route, std::uint32_t hops, Service& next, const Error& error, bool posted) {
  const auto first = route[0];
  const auto last = route[hops - 1];
  if (posted) {
    auto held = Status::pack(first.ticket, CellState::forwarding);
    if (!next.cell(first.cell).status.compare_exchange_strong(held, Status::pack(first.ticket + 1, CellState::free)))
      next.free_abandoned(first.cell, first.ticket);
    return free_posted(route, 1, hops);
  }
  if (hops > 1) {
    auto held = Status::pack(first.ticket, CellState::forwarding);
    if (!next.cell(first.cell).status.compare_exchange_strong(held, Status::pack(first.ticket, CellState::claimed)))
      next.free_abandoned(first.cell, first.ticket);
  }
  Service* end = hops > 1 ? following(last) : &next;
  if (!end || (hops > 1 && !take_over(*end, last))) return;
  auto& to = end->cell(last.cell);
  write_error(to, end->tail(last.cell), error);
  auto held = Status::pack(last.ticket, CellState::forwarding);
  if (to.status.compare_exchange_strong(held, Status::pack(last.ticket, CellState::failed)))
    end->tail(last.cell).answered.ring();
  else
    end->free_abandoned(last.cell, last.ticket);
}

// Frees the cells a post's route holds from `from` on, claimed for
// outputs that will never come (no caller of a post frees them).
void Server::free_posted(const Hop* route, std::uint32_t from, std::uint32_t hops) {
  for (std::uint32_t k = from; k < hops; ++k) {
    Service* at = following(route[k]);
    if (!at || !at->has_cell(route[k].cell)) continue;
    auto claimed = Status::pack(route[k].ticket, CellState::claimed);
    at->cell(route[k].cell).status.compare_exchange_strong(claimed, Status::pack(route[k].ticket + 1, CellState::free));
  }
}

void Server::write_error(CellHeader& c, CellTail& tail, const Error& error) {
  c.errc = static_cast<std::uint32_t>(error.code);
  const auto n = std::min(error.message.size(), kErrorCapacity - 1);
  std::memcpy(tail.error, error.message.data(), n);
  tail.error[n] = '\0';
}

Service* Server::following(const Hop& hop) {
  std::scoped_lock lock{mutex_};
  // Kept only for entries the registry names: a hop is read from shared
  // memory, and the map must not grow with every value a caller writes.
  auto found = next_.find(hop.service);
  // The segment the hop's caller holds its cell in, mapped already: no
  // look at the name (a path and two system calls) on each call.
  if (found != next_.end() && found->second && found->second->header().incarnation == hop.incarnation)
    return found->second.get();
  if (found == next_.end() || !found->second || !found->second->current()) {
    const auto name = service_->registry().name_at(hop.service, EndpointKind::service);
    if (!name) return nullptr;
    std::shared_ptr<Service> opened;
    try {
      opened = Service::open_existing(service_->registry_handle(), *name);
    } catch (const Failure&) {
      return nullptr;  // damaged: as if it were gone
    }
    found = next_.insert_or_assign(hop.service, std::move(opened)).first;
  }
  const auto& known = found->second;
  if (!known || known->header().incarnation != hop.incarnation) return nullptr;  // made anew since: that cell is gone
  return known.get();
}

// After a server that died: what it was running fails (its callers are
// told), what waited is queued again, what was abandoned is freed; and so
// is the next service's cell a linked call it ran held for its output.
void Server::recover() {
  auto& h = service_->header();
  for (std::size_t i = 0; i < service_->geometry().cell_count(); ++i) {
    auto& c = service_->cell(i);
    const auto s = c.status.load();
    const auto ticket = Status::ticket(s);
    switch (Status::state(s)) {
      case CellState::running: {
        recover_route(i, CellState::running);
        auto running = s;
        if (c.posted) {  // no one waits for a post's answer, nor releases its cell: freed here
          if (!c.status.compare_exchange_strong(running, Status::pack(ticket + 1, CellState::free)))
            service_->free_abandoned(i, ticket);
          break;
        }
        write_error(c, service_->tail(i), {Errc::peer_dead, "service '" + service_->name() + "': its server died while running this call"});
        if (c.status.compare_exchange_strong(running, Status::pack(ticket, CellState::failed))) service_->tail(i).answered.ring();
        else service_->free_abandoned(i, ticket);  // its caller gave up meanwhile
        break;
      }
      case CellState::queued:
        h.pending[i / 64].fetch_or(1ull << (i % 64));
        break;
      case CellState::abandoned:
        recover_route(i, CellState::abandoned);
        service_->free_abandoned(i, ticket);
        break;
      default:
        break;
    }
  }
}

// A linked call in cell `i` that a dead worker was running (or that its
// caller abandoned meanwhile): the next service's cell, which that worker
// may have taken for its output, does not wait for an answer that never
// comes. Running, the call fails as fail_linked fails it (the caller,
// waiting on its last cell, is told); abandoned, the cell is freed.
void Server::recover_route(std::size_t i, CellState state) {
  const std::uint32_t hops = service_->cell(i).next_hops;
  if (hops == 0 || hops >= kMaxHops) return;
  Hop route[kMaxHops - 1];
  std::copy(service_->tail(i).next, service_->tail(i).next + hops, route);
  Service* next = following(route[0]);
  if (!next || !next->has_cell(route[0].cell)) {
    if (state == CellState::running && service_->cell(i).posted) free_posted(route, 1, hops);
    return;
  }
  if (state == CellState::abandoned) return next->free_abandoned(route[0].cell, route[0].ticket);
  auto& status = next->cell(route[0].cell).status;
  auto claimed = Status::pack(route[0].ticket, CellState::claimed);
  const bool held = status.load() == Status::pack(route[0].ticket, CellState::forwarding) ||
                    status.compare_exchange_strong(claimed, Status::pack(route[0].ticket, CellState::forwarding));
  if (held)
    fail_linked(route, hops, *next,
                {Errc::peer_dead, "service '" + service_->name() + "': its server died while running this call"},
                service_->cell(i).posted != 0);
  else
    next->free_abandoned(route[0].cell, route[0].ticket);
}

}  // namespace prime::shm::detail
