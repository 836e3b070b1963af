#pragma once

#include <chrono>
#include <cstddef>
#include <cstdint>
#include <functional>
#include <map>
#include <memory>
#include <mutex>
#include <optional>
#include <stop_token>
#include <string>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/shm/detail/service.hpp"
#include "prime/shm/service_handles.hpp"

namespace prime::shm::detail {

// The one live server of a service: it takes the service over (after one
// that died, where that one stopped) and its workers answer calls, each in
// place in the caller's cell, or, in a linked call, in the next service's.
//
// Thread-safe: each worker runs `work` on a thread of its own.
class Server {
 public:
  // Takes `service` over (Errc::in_use while another server of it lives),
  // and recovers what a server that died left in its cells.
  Server(std::shared_ptr<Service> service, const ServiceQos& qos, Handler handler, std::function<void(Error)> report);
  Server(const Server&) = delete;
  Server& operator=(const Server&) = delete;
  ~Server();

  // One worker: takes requests until `stop`, sleeping when there are none.
  void work(std::size_t index, const std::stop_token& stop);

 private:
  // A queued cell, now this worker's to look at, if one is still pending.
  std::optional<std::size_t> take(std::size_t& start);
  // Runs the call in cell `i` and answers it, or hands a linked call's
  // output on to the next service.
  void serve(std::size_t i);
  // Takes the caller's cell in the next service for writing, if the caller
  // still waits for it (and the cell is one the service has).
  static bool take_over(Service& next, const Hop& hop);
  // Answers the caller in this cell: done (or failed with `error`), and
  // wakes it; a posted call's cell is simply freed.
  void answer(std::size_t i, std::uint64_t ticket, const Error* error);
  // Ends this worker's hold of cell `i` without an answer in it: the caller
  // frees it (or, `free`, it is freed now).
  void finish(std::size_t i, std::uint64_t ticket, bool free);
  // A linked call failed here, while this worker holds the next cell of its
  // `route` (`hops` long), forwarding: the error goes where its caller
  // waits, and the cells go back (see the definition).
  void fail_linked(const Hop* route, std::uint32_t hops, Service& next, const Error& error, bool posted);
  // Frees the cells a post's route holds from `from` on.
  void free_posted(const Hop* route, std::uint32_t from, std::uint32_t hops);
  static void write_error(CellHeader& c, CellTail& tail, const Error& error);
  // The service `hop` goes to, mapped here: the segment its registry entry
  // names now, if that is still the one the hop's caller held a cell in.
  Service* following(const Hop& hop);
  // After a server that died: what it was running fails, what waited is
  // queued again, what was abandoned is freed (see the definition).
  void recover();
  // A linked call in cell `i` that a dead worker was running, or that its
  // caller abandoned: the next service's cell it held is given back.
  void recover_route(std::size_t i, CellState state);

  std::shared_ptr<Service> service_;
  std::chrono::microseconds spin_;
  Handler handler_;
  std::function<void(Error)> report_;
  std::mutex mutex_;
  std::map<std::uint32_t, std::shared_ptr<Service>> next_;  // services this one forwards to
};

}  // namespace prime::shm::detail
