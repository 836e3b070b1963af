// A client's side of Shm services: its binding to each service (segment,
// client slot, the server it last saw alive) and a call down a route.
#include "prime/shm/detail/caller.hpp"

#include <algorithm>
#include <array>
#include <thread>

#include "prime/topology/detail/wait.hpp"

namespace prime::shm::detail {

namespace {

std::unexpected<Error> not_found(std::string message) {
  return std::unexpected(Error{Errc::not_found, std::move(message)});
}
std::unexpected<Error> limit(const Service& service, Errc code, const std::string& what) {
  return std::unexpected(Error{code, "service '" + service.name() + "': " + what});
}

}  // namespace

Binding::~Binding() { unbind(); }

std::expected<std::shared_ptr<Service>, Error> Binding::ready(Clock::time_point now) {
  auto bound = bind(now);
  if (bound || bound.error().code != Errc::not_found || qos_.wait_for_service <= Clock::duration::zero()) return bound;
  const auto give_up = deadline_after(qos_.wait_for_service, now);
  auto pause = std::chrono::microseconds{100};
  while (true) {
    bound = bind(Clock::now());
    if (bound || bound.error().code != Errc::not_found || Clock::now() >= give_up) return bound;
    std::this_thread::sleep_for(std::min<Clock::duration>(pause, give_up - Clock::now()));
    pause = std::min(pause * 2, std::chrono::microseconds{10000});
  }
}

std::expected<std::size_t, Error> Binding::claim(Service& service, Clock::time_point at) {
  auto& h = service.header();
  const auto now = at.time_since_epoch().count();
  auto& slot = h.clients[slot_];
  const auto gap = h.min_interval_ns.load(std::memory_order_relaxed);
  const auto last = slot.last_request.load();
  if (gap > 0 && last != 0 && last <= now && now - last < gap)
    return limit(service, Errc::rate_limited, "a client sends at most one request every " + std::to_string(gap / 1000) +
                              " us (min_interval)");
  if (const auto depth = h.queue_depth.load(); depth > 0 && service.queued() >= depth)
    return limit(service, Errc::queue_full, std::to_string(depth) + " requests wait for a worker already (queue_depth)");
  const auto calls = service.geometry().calls_per_client;
  const auto first = slot_ * calls;
  for (std::size_t k = 0; k < calls; ++k) {
    auto& status = service.cell(first + k).status;
    auto s = status.load();
    if (Status::state(s) != CellState::free) continue;
    if (status.compare_exchange_strong(s, Status::pack(Status::ticket(s), CellState::claimed))) {
      if (gap > 0) slot.last_request.store(now, std::memory_order_relaxed);
      return first + k;
    }
  }
  return limit(service, Errc::queue_full, "this client has " + std::to_string(calls) +
                            " calls in flight already (calls_per_client)");
}

std::expected<std::shared_ptr<Service>, Error> Binding::bind(Clock::time_point now) {
  std::scoped_lock lock{mutex_};
  // The fast path: bound, the same server as when last looked at, and that
  // not long ago. Looking at a lease costs a system call; a server that
  // died since is seen by the next look, or by a waiting call's.
  if (service_ && service_->header().server.load(std::memory_order_relaxed) == checked_server_ && checked_server_ != 0 &&
      now < checked_until_)
    return service_;
  if (service_ && !live(*service_)) {
    // Its server is gone: a new one may serve a new segment under the name.
    if (!service_->current()) release_slot();
  }
  if (!service_) {
    std::shared_ptr<Service> found;
    try {
      found = Service::open_existing(registry_, name_);
    } catch (const Failure& damaged) {
      return std::unexpected(damaged.error());
    }
    if (!found) return not_found("no service '" + name_ + "' in domain '" + registry_->domain() + "'");
    auto& h = found->header();
    if (!(h.request_type == request_) || !(h.reply_type == reply_))
      return std::unexpected(Error{Errc::type_mismatch, "service '" + name_ + "' takes " + h.request_type.describe() +
                                                            " and gives " + h.reply_type.describe() + ", not " +
                                                            request_.describe() + " and " + reply_.describe()});
    if (const auto& g = found->geometry(); g.max_request_size < request_.size || g.max_reply_size < reply_.size)
      return std::unexpected(Error{Errc::damaged, "service '" + name_ + "': its shared memory is damaged (cells of " +
                                                      std::to_string(g.max_request_size) + "-byte requests and " +
                                                      std::to_string(g.max_reply_size) + "-byte replies for " +
                                                      request_.describe() + " and " + reply_.describe() + ")"});
    if (auto taken = take_slot(*found); !taken) return std::unexpected(std::move(taken.error()));
    service_ = std::move(found);
  }
  const auto server = service_->header().server.load();
  if (server == 0) return not_found("service '" + name_ + "' has no server (none started, or it stopped)");
  if (!registry_->alive(server))
    return not_found("service '" + name_ + "' has no live server: " + registry_->describe(server) + " died");
  checked_server_ = server;
  checked_until_ = now + std::chrono::milliseconds{1};
  return service_;
}

std::expected<void, Error> Binding::take_slot(Service& service) {
  auto& h = service.header();
  for (int pass = 0; pass < 2; ++pass) {
    for (std::size_t c = 0; c < service.geometry().max_clients; ++c) {
      ParticipantId free = 0;
      if (h.clients[c].owner.compare_exchange_strong(free, registry_->me())) {
        slot_ = c;
        return {};
      }
    }
    if (service.reclaim_dead_clients() == 0) break;
  }
  return std::unexpected(Error{Errc::too_many_clients, "service '" + name_ + "' has its maximum of " +
                                                         std::to_string(service.geometry().max_clients) + " clients (max_clients)"});
}

void Binding::release_slot(bool keep_posts) {
  if (!service_) return;
  auto& h = service_->header();
  const auto calls = service_->geometry().calls_per_client;
  for (std::size_t k = 0; k < calls; ++k) {
    const auto i = slot_ * calls + k;
    const auto state = Status::state(service_->cell(i).status.load());
    const bool post_under_way = service_->cell(i).posted != 0 && state != CellState::free && state != CellState::abandoned;
    if (!keep_posts || !post_under_way) service_->release(i);
  }
  h.clients[slot_].owner.store(0);
  service_.reset();
}

void Binding::unbind() {
  std::scoped_lock lock{mutex_};
  release_slot(true);
}

std::expected<void, Error> call(const Route& route, const RequestWriter& write, const ReplyReader& read, bool posted,
                                const GiveUp& give_up) {
  struct Held {
    std::shared_ptr<Service> service;
    std::size_t cell = 0;
    std::uint64_t ticket = 0;
  };
  struct Cells {  // the cells this call holds, one per service of the route (no allocation per call)
    std::array<Held, kMaxHops> at;
    std::size_t count = 0;
    Held* begin() { return at.data(); }
    Held* end() { return at.data() + count; }
    Held& front() { return at[0]; }
    Held& back() { return at[count - 1]; }
    std::size_t size() const { return count; }
    Held& operator[](std::size_t i) { return at[i]; }
  } held;
  auto release_all = [&] {
    for (auto& h : held) h.service->release(h.cell, h.ticket);
  };
  const auto now = Clock::now();
  for (const auto& binding : route) {
    auto service = binding->ready(now);
    if (!service) {
      release_all();
      return std::unexpected(std::move(service.error()));
    }
    auto cell = binding->claim(**service, now);
    if (!cell) {
      release_all();
      return std::unexpected(std::move(cell.error()));
    }
    held.at[held.count++] = {std::move(*service), *cell, 0};
    held.back().ticket = Status::ticket(held.back().service->cell(*cell).status.load());
  }

  // The call's deadline: the client's timeout, or the longest its services
  // allow (a server sets its limits just after it takes the service: one
  // found with none yet allows the default).
  auto timeout = saturating_cast<std::chrono::nanoseconds>(route.front()->qos().timeout);
  if (timeout == std::chrono::nanoseconds::zero())
    for (auto& h : held) timeout = std::max(timeout, std::chrono::nanoseconds{h.service->header().timeout_ns.load()});
  if (timeout == std::chrono::nanoseconds::zero()) timeout = ServiceQos{}.timeout;
  const auto deadline = deadline_after(timeout, now);

  auto& first = held.front();
  auto& c = first.service->cell(first.cell);
  try {
    c.request_size = write(first.service->request(first.cell), first.service->geometry().max_request_size);
  } catch (const Failure& f) {
    release_all();
    return std::unexpected(f.error());
  }
  c.stamp = now.time_since_epoch().count();
  c.posted = posted ? 1 : 0;
  c.next_hops = static_cast<std::uint32_t>(held.size() - 1);
  for (std::size_t k = 1; k < held.size(); ++k)
    first.service->tail(first.cell).next[k - 1] = {held[k].service->index(), static_cast<std::uint32_t>(held[k].cell),
                                                   held[k].ticket, held[k].service->header().incarnation};
  // Every cell of the route says whether it is posted (its worker then
  // frees it), as the first does: a cell a post left marked, taken by a
  // call, would be freed unanswered where the call fails before reaching it.
  for (std::size_t k = 1; k < held.size(); ++k) held[k].service->cell(held[k].cell).posted = posted ? 1 : 0;
  c.status.store(Status::pack(first.ticket, CellState::queued), std::memory_order_release);
  first.service->header().requests_in.fetch_add(1, std::memory_order_relaxed);
  first.service->enqueue(first.cell);
  if (posted) return {};

  // Wait for the last cell: spinning, then asleep in slices, looking after
  // each at the servers of the route (a dead one is reported within ~25 ms).
  auto& last = held.back();
  auto& answer = last.service->cell(last.cell);
  const auto done = Status::pack(last.ticket, CellState::done);
  const auto failed = Status::pack(last.ticket, CellState::failed);
  auto answered = [&] {
    const auto s = answer.status.load(std::memory_order_acquire);
    return s == done || s == failed;
  };
  std::optional<Error> gone;
  // A server gone before any worker took the request means there was no
  // service to call (not_found); gone after, that the call died with it.
  auto check = [&] {
    const bool taken = first.service->cell(first.cell).status.load() != Status::pack(first.ticket, CellState::queued);
    for (auto& h : held) {
      const auto server = h.service->header().server.load();
      if (server == 0)
        gone = Error{Errc::stopped, "service '" + h.service->name() + "' stopped while this call waited"};
      else if (!h.service->registry().alive(server))
        gone = taken ? Error{Errc::peer_dead, "service '" + h.service->name() + "': its server, " +
                                                  h.service->registry().describe(server) + ", died while this call waited"}
                     : Error{Errc::not_found, "service '" + h.service->name() + "' has no live server: " +
                                                  h.service->registry().describe(server) + " died"};
    }
  };
  auto over = [&] { return answered() || gone.has_value(); };
  auto sleep = [&](Clock::time_point until) {
    last.service->tail(last.cell).answered.sleep_until(1, answered, std::min(until, Clock::now() + std::chrono::milliseconds{25}));
    if (answered()) return;
    check();
    if (!gone && give_up && give_up())
      gone = Error{Errc::stopped,
                   "service '" + route.front()->name() + "': the caller gave this call up while it waited"};
  };
  (void)prime::detail::spin_then_sleep(prime::detail::yielding(over), sleep, route.back()->qos().spin, deadline, std::stop_token{}, now);
  if (!answered()) {
    release_all();
    // A cell a worker held for its output (forwarding) is now abandoned to
    // it. One of a server that is dead (or stopped) is held by no one, and
    // freed here. Looked at after the release, which leaves no cell for a
    // newly started server's worker to take: a worker holding one now is
    // one whose server is registered, so seen alive.
    for (std::size_t k = 1; k < held.size(); ++k) {
      const auto& before = *held[k - 1].service;
      if (const auto server = before.header().server.load(); server != 0 && before.registry().alive(server)) continue;
      held[k].service->free_abandoned(held[k].cell, held[k].ticket);
    }
    if (gone) return std::unexpected(std::move(*gone));
    return std::unexpected(Error{Errc::timeout, "service '" + route.front()->name() + "': no answer within the call's timeout"});
  }
  std::expected<void, Error> result;
  if (answer.status.load() == failed) {
    result = std::unexpected(Error{errc_from(static_cast<int>(answer.errc)).value_or(Errc::block_failed),
                                   last.service->error(last.cell)});
  } else {
    try {
      read(last.service->reply(last.cell), last.service->reply_size(answer));
    } catch (const Failure& f) {
      result = std::unexpected(f.error());
    }
  }
  release_all();
  return result;
}

Route linked(const Route& first, const Route& second) {
  const auto& out = first.back();
  const auto& in = second.front();
  if (!forwards_into(out->reply(), in->request()))
    throw Failure{{Errc::type_mismatch, "cannot link service '" + out->name() + "', which gives " + out->reply().describe() +
                                            ", to service '" + in->name() + "', which takes " + in->request().describe()}};
  auto route = first;
  route.insert(route.end(), second.begin(), second.end());
  if (route.size() > kMaxHops)
    throw Failure{{Errc::invalid_argument, "a linked call goes through at most " + std::to_string(kMaxHops) +
                                             " services, not " + std::to_string(route.size())}};
  return route;
}

}  // namespace prime::shm::detail
