#pragma once

#include <algorithm>
#include <atomic>
#include <bit>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <new>
#include <optional>
#include <string>

#include "prime/common/fingerprint.hpp"
#include "prime/common/fixed_text.hpp"
#include "prime/logic/error.hpp"
#include "prime/shm/detail/registry.hpp"
#include "prime/shm/detail/segment.hpp"
#include "prime/shm/detail/service_layout.hpp"
#include "prime/shm/detail/typed_segment.hpp"
#include "prime/shm/message.hpp"
#include "prime/shm/qos.hpp"

namespace prime::shm::detail {

// Whether a linked call may write a reply of type `reply` into a request
// cell of type `request`: the same type, or bytes, which a service of
// Bytes takes whatever they are (each write is checked against the cell).
inline bool forwards_into(const Fingerprint& reply, const Fingerprint& request) {
  return reply == request || request == Fingerprint::of<Bytes>();
}

// The types and limits a service is made with: what its segment records.
struct ServiceSpec {
  Fingerprint request_type;
  Fingerprint reply_type;
  ServiceQos qos;  // complete: sizes and depths filled in
  std::string request_schema{};
  std::string reply_schema{};
};

// A service's segment mapped into this process: by its server, and by each
// client. Thread-safe (shared state is atomic or fixed at creation).
class Service {
 public:
  // For a server: `name` made for `spec`. A segment left for other types or
  // limits by a server that is gone is made anew (its clients find the new
  // one by name); one whose server lives is Errc::in_use.
  static std::shared_ptr<Service> open_to_serve(std::shared_ptr<Registry> registry, const std::string& name,
                                                const ServiceSpec& spec);

  // For a client: the service `name` as it is, or null when there is none.
  // Throws Failure (Errc::damaged) when its header is damaged.
  static std::shared_ptr<Service> open_existing(std::shared_ptr<Registry> registry, const std::string& name);

  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  [[nodiscard]] std::uint32_t index() const noexcept { return index_; }  // its registry entry
  [[nodiscard]] Registry& registry() const noexcept { return *registry_; }
  [[nodiscard]] const std::shared_ptr<Registry>& registry_handle() const noexcept { return registry_; }
  // Its shared state. What it fixed at creation is read through
  // geometry(), never here: see ServiceGeometry.
  [[nodiscard]] ServiceHeader& header() const noexcept { return *header_; }
  [[nodiscard]] const ServiceGeometry& geometry() const noexcept { return mapped_.geometry(); }
  // Whether `i` names one of its cells: an index read from shared memory
  // (a pending bit, a linked call's hop) is checked before it is used.
  [[nodiscard]] bool has_cell(std::size_t i) const noexcept { return i < geometry().cell_count(); }
  [[nodiscard]] CellHeader& cell(std::size_t i) const noexcept {
    return *std::launder(reinterpret_cast<CellHeader*>(cells_ + i * stride_));
  }
  [[nodiscard]] CellTail& tail(std::size_t i) const noexcept {
    return *std::launder(reinterpret_cast<CellTail*>(cells_ + i * stride_ + geometry().tail_offset()));
  }
  [[nodiscard]] std::byte* request(std::size_t i) const noexcept {
    return cells_ + i * stride_ + geometry().request_offset();
  }
  [[nodiscard]] std::byte* reply(std::size_t i) const noexcept { return cells_ + i * stride_ + geometry().reply_offset(); }
  // A request's or reply's size as shared memory records it, within its room.
  [[nodiscard]] std::size_t request_size(const CellHeader& c) const noexcept {
    return static_cast<std::size_t>(std::min<std::uint64_t>(c.request_size, geometry().max_request_size));
  }
  [[nodiscard]] std::size_t reply_size(const CellHeader& c) const noexcept {
    return static_cast<std::size_t>(std::min<std::uint64_t>(c.reply_size, geometry().max_reply_size));
  }
  // The error a failed call's cell carries.
  [[nodiscard]] std::string error(std::size_t i) const { return read_text(tail(i).error); }
  // Whether the name still leads to this segment (a server that came back
  // for other types made a new one).
  [[nodiscard]] bool current() const { return mapped_.segment().linked(); }

  [[nodiscard]] ServiceQos qos() const noexcept;

  // Requests waiting for a worker.
  [[nodiscard]] std::size_t queued() const noexcept {
    std::size_t n = 0;
    for (const auto& word : header_->pending) n += static_cast<std::size_t>(std::popcount(word.load(std::memory_order_relaxed)));
    return n;
  }

  // Queues cell `i` for a worker (its status already says queued).
  void enqueue(std::size_t i) {
    header_->pending[i / 64].fetch_or(1ull << (i % 64), std::memory_order_seq_cst);
    wake_workers();
  }

  // Wakes idle workers. If the bits of sleepers stay raised while no one
  // wakes, the server died with its workers asleep: forget them.
  void wake_workers() {
    if (header_->requests.ring() != 0) return;
    if (!registry_->alive(header_->server.load())) header_->requests.forget(~0ull);
  }

  // Frees the cells and slot of every client whose participant is gone.
  // What a live worker holds is abandoned instead: that worker frees it.
  std::size_t reclaim_dead_clients() const;

  // Lets go of cell `i` for whoever holds it: frees it, or, while a worker
  // holds it, marks it abandoned for that worker to free. With `only`, only
  // while it still carries that ticket (the call it was claimed for): once
  // freed, it may carry another call of the same client.
  void release(std::size_t i, std::optional<std::uint64_t> only = std::nullopt) const {
    auto& status = cell(i).status;
    auto s = status.load();
    while (true) {
      const auto state = Status::state(s);
      const auto ticket = Status::ticket(s);
      if (state == CellState::free || state == CellState::abandoned || (only && ticket != *only)) return;
      const auto next = state == CellState::running || state == CellState::forwarding
                            ? Status::pack(ticket, CellState::abandoned)
                            : Status::pack(ticket + 1, CellState::free);
      if (status.compare_exchange_weak(s, next)) return;
    }
  }

  // Frees cell `i` if it was abandoned with `ticket`.
  void free_abandoned(std::size_t i, std::uint64_t ticket) const {
    auto expected = Status::pack(ticket, CellState::abandoned);
    cell(i).status.compare_exchange_strong(expected, Status::pack(ticket + 1, CellState::free));
  }

 private:
  using Mapped = TypedSegment<ServiceHeader, ServiceGeometry>;

  Service(std::shared_ptr<Registry> registry, std::string name, std::size_t index, Mapped mapped);

  std::shared_ptr<Registry> registry_;
  std::string name_;
  std::uint32_t index_;
  Mapped mapped_;
  ServiceHeader* header_;  // mapped_'s, at hand
  std::byte* cells_;
  std::size_t stride_;  // from one cell to the next
};

}  // namespace prime::shm::detail
