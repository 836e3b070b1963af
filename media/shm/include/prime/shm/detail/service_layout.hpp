#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <string>

#include "prime/common/fingerprint.hpp"
#include "prime/shm/detail/doorbell.hpp"
#include "prime/shm/detail/layout.hpp"

namespace prime::shm::detail {

// What lives in a service's shared memory: plain data and lock-free atomics
// addressed by offsets, like a topic's.
//
//   ServiceHeader | cells: cell_count × (CellHeader | reply | request | CellTail)
//
// A call lives in a cell of its caller's client slot: the caller writes the
// request there, a worker reads it in place and writes the answer beside it,
// the caller reads that in place. A request waits for a worker as one bit
// of `pending`; a busy worker polls that one line, a sleeping one is rung.
// Each cell's status word carries a ticket that changes whenever the cell
// is freed, so an answer meant for a call that gave up never reaches a later one.

inline constexpr std::size_t kMaxCells = 256;
inline constexpr std::size_t kPendingWords = kMaxCells / 64;
inline constexpr std::size_t kMaxServiceClients = 128;
inline constexpr std::size_t kMaxWorkers = 62;
inline constexpr std::size_t kMaxHops = 8;  // services one linked call goes through
inline constexpr std::size_t kErrorCapacity = 256;

// Where a call stands. The caller claims a free cell, writes its request and
// queues it; a worker takes it (running) and answers (done or failed) — or,
// in a linked call, writes its output into the next service's cell, which it
// holds meanwhile (forwarding), and queues that. A caller that stops waiting
// frees what no worker holds and abandons what one does; that worker frees
// it when it finishes.
enum class CellState : std::uint8_t { free, claimed, queued, running, forwarding, done, failed, abandoned };

// A cell's status: its ticket and its state, in one word so that every
// change is one compare-and-swap against both.
struct Status {
  static constexpr std::uint64_t pack(std::uint64_t ticket, CellState state) noexcept {
    return (ticket << 8) | static_cast<std::uint8_t>(state);
  }
  static constexpr std::uint64_t ticket(std::uint64_t status) noexcept { return status >> 8; }
  static constexpr CellState state(std::uint64_t status) noexcept { return static_cast<CellState>(status & 0xff); }
};

// The next service a linked call goes on to: the registry entry that names
// it, which of the segments made under that name (its incarnation), and the
// cell (and ticket) its caller holds there.
struct Hop {
  std::uint32_t service = 0;
  std::uint32_t cell = 0;
  std::uint64_t ticket = 0;
  std::uint64_t incarnation = 0;
};

// A cell is its header line, the reply, the request and its tail, in that
// order: the line a caller polls and the first line of its answer are
// neighbours, which the hardware fetches together.
struct alignas(64) CellHeader {
  std::atomic<std::uint64_t> status{Status::pack(0, CellState::free)};
  std::uint64_t request_size = 0;
  std::uint64_t reply_size = 0;
  std::int64_t stamp = 0;       // the request's, carried to the answer
  std::uint32_t posted = 0;     // no answer wanted: the worker frees the cell
  std::uint32_t errc = 0;       // Errc of a failed call
  std::uint32_t next_hops = 0;  // entries of the tail's `next` this call goes on to
};
static_assert(sizeof(CellHeader) == 64, "a cell's header is the one line a caller polls");

struct CellTail {
  Hop next[kMaxHops - 1];
  char error[kErrorCapacity]{};
  Doorbell answered;  // the caller sleeps here
};

struct alignas(64) ClientSlot {
  std::atomic<ParticipantId> owner{0};
  std::atomic<std::int64_t> last_request{0};  // steady_clock ticks
};
static_assert(sizeof(ClientSlot) == 64);

struct ServiceHeader {
  static constexpr const char* kKind = "service";  // in its segment's name (and TypedSegment's errors)
  static constexpr std::uint64_t kMagic = kServiceMagic;
  static constexpr std::uint32_t kLayout = kServiceLayout;

  std::atomic<std::uint64_t> magic{0};  // kServiceMagic once the creator has set everything below
  std::uint32_t layout = kServiceLayout;
  std::atomic<std::uint32_t> workers{0};  // the current server's
  // Drawn at random when the segment is made: a segment made anew under the
  // same name (a server with other limits) is another incarnation, so a
  // linked call that held a cell of the old one never takes the new one's.
  std::uint64_t incarnation = 0;
  Fingerprint request_type{};
  Fingerprint reply_type{};
  char request_schema[kSchemaCapacity]{};  // the types' descriptions, for tools
  char reply_schema[kSchemaCapacity]{};
  std::uint64_t max_request_size = 0;
  std::uint64_t max_reply_size = 0;
  std::uint64_t max_clients = 0;
  std::uint64_t calls_per_client = 0;
  // The current server's limits, which a server that takes over sets anew.
  std::atomic<std::uint64_t> queue_depth{0};
  std::atomic<std::int64_t> min_interval_ns{0};
  std::atomic<std::int64_t> timeout_ns{0};
  std::uint64_t cell_count = 0;
  std::uint64_t cell_stride = 0;
  std::uint64_t request_offset = 0;  // within a cell
  std::uint64_t reply_offset = 0;
  std::uint64_t tail_offset = 0;
  std::uint64_t cells_offset = 0;

  alignas(64) std::atomic<ParticipantId> server{0};
  alignas(64) std::atomic<std::uint64_t> pending[kPendingWords]{};
  Doorbell requests;  // idle workers sleep here, one bit each
  // Counters, each on the line of whoever writes it, so counting costs no
  // transfer between caller and worker.
  alignas(64) std::atomic<std::uint64_t> requests_in{0};   // queued by callers
  alignas(64) std::atomic<std::uint64_t> forwarded_in{0};  // queued by the service before it in a linked call
  alignas(64) std::atomic<std::uint64_t> served{0};        // calls answered (by the workers from here on)
  std::atomic<std::uint64_t> failed{0};                    // calls answered with an error
  std::atomic<std::uint64_t> replies_out{0};               // answers to callers
  std::atomic<std::uint64_t> forwarded_out{0};             // outputs written into the next service's cell
  ClientSlot clients[kMaxServiceClients];
};
static_assert(offsetof(ServiceHeader, pending) % 64 == 0 && offsetof(ServiceHeader, clients) % 64 == 0);

// Where the parts of a service's segment lie, from its limits. As a topic's
// (TopicGeometry): a process reads it from the header once, checks it and
// goes by that copy from then on.
struct ServiceGeometry {
  std::size_t max_request_size;
  std::size_t max_reply_size;
  std::size_t max_clients;
  std::size_t calls_per_client;

  // What `h` records, read once.
  [[nodiscard]] static ServiceGeometry of(const ServiceHeader& h) noexcept {
    return {h.max_request_size, h.max_reply_size, h.max_clients, h.calls_per_client};
  }

  [[nodiscard]] constexpr std::size_t cell_count() const { return max_clients * calls_per_client; }

  [[nodiscard]] constexpr std::size_t reply_offset() const { return sizeof(CellHeader); }
  [[nodiscard]] constexpr std::size_t request_offset() const { return reply_offset() + round_up(max_reply_size, 64); }
  [[nodiscard]] constexpr std::size_t tail_offset() const { return request_offset() + round_up(max_request_size, 64); }
  [[nodiscard]] constexpr std::size_t cell_stride() const { return round_up(tail_offset() + sizeof(CellTail), 64); }
  [[nodiscard]] constexpr std::size_t cells_offset() const { return round_up(sizeof(ServiceHeader), 64); }
  [[nodiscard]] constexpr std::size_t bytes() const { return cells_offset() + cell_count() * cell_stride(); }

  // Which of its values is out of bounds, when one is (as a topic's:
  // TopicGeometry::out_of_bounds); empty when none is.
  [[nodiscard]] std::string out_of_bounds() const {
    if (max_clients == 0 || max_clients > kMaxServiceClients)
      return std::to_string(max_clients) + " client slots, not in [1, " + std::to_string(kMaxServiceClients) + "]";
    if (calls_per_client == 0 || calls_per_client > kMaxCells || cell_count() > kMaxCells)
      return std::to_string(max_clients) + " clients of " + std::to_string(calls_per_client) + " calls, not in [1, " +
             std::to_string(kMaxCells) + "] cells";
    if (max_request_size >= kMaxMessageSize || max_reply_size >= kMaxMessageSize)
      return "requests of " + std::to_string(max_request_size) + " bytes and replies of " + std::to_string(max_reply_size) +
             " (each below 2^40 bytes)";
    return {};
  }
};

// What is wrong with geometry `g`, read from header `h`, against the
// `size`-byte segment `h` heads; empty when nothing is (as for a topic's:
// see damage(TopicHeader, TopicGeometry)).
inline std::string damage(const ServiceHeader& h, const ServiceGeometry& g, std::size_t size) {
  if (auto what = g.out_of_bounds(); !what.empty()) return what;
  if (h.cell_count != g.cell_count())
    return std::to_string(h.cell_count) + " cells for " + std::to_string(g.max_clients) + " clients of " +
           std::to_string(g.calls_per_client) + " calls";
  if (h.cell_stride != g.cell_stride() || h.request_offset != g.request_offset() || h.reply_offset != g.reply_offset() ||
      h.tail_offset != g.tail_offset() || h.cells_offset != g.cells_offset())
    return "a layout that does not follow from its message sizes and cells";
  if (g.bytes() > size) return std::to_string(g.bytes()) + " bytes of layout in a segment of " + std::to_string(size);
  return {};
}

}  // namespace prime::shm::detail
