#pragma once

#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>

namespace prime {

// What went wrong on the data path. `stopped` (the owner shut down) is kept
// apart from the failures, so a worker can tell "leave now" from "report this".
enum class Errc {
  // The numbers travel (a service's error in shared memory, an Optimus
  // reply): a code keeps its number, a retired one's is not reused.
  timeout = 0,         // a deadline passed before a value arrived or room was made
  stopped = 1,         // the core or worker that owns the endpoint is shutting down
  no_data = 2,         // a reader was asked for a value none has published yet
  overflow = 3,        // a value was dropped: a bounded buffer was full
  block_failed = 4,    // a user's block threw; `message` carries what it said
  // 5 was limit_exceeded, split into the codes from 14 on
  type_mismatch = 6,   // an endpoint was opened with another type than it carries
  peer_dead = 7,       // the process on the other side is gone
  unreachable = 8,     // a server could not be reached
  in_use = 9,          // a name that admits one owner (a topic's publisher) has a live one
  qos_mismatch = 10,   // an endpoint exists with other QoS than this side asks for
  no_space = 11,       // memory for an endpoint could not be reserved (a full /dev/shm)
  not_found = 12,      // no endpoint of that name exists (a service nobody serves)
  damaged = 13,        // bytes another process left (shared memory, a Redis entry) break their own bounds
  invalid_argument = 14,      // a name, an option or a QoS value the call cannot take
  too_large = 15,             // a message, request, reply or batch over its size limit
  queue_full = 16,            // every place of a bounded queue is taken (loans, requests, calls in flight)
  too_many_subscribers = 17,  // a topic has its maximum of subscribers (max_subscribers), or its observer
  too_many_clients = 18,      // a service has its maximum of clients (max_clients)
  domain_full = 19,           // a domain has its maximum of participants, or of topics and services
  rate_limited = 20,          // a client asked again sooner than its service lets one (min_interval)
  held_limit = 21,            // a reader holds as many values as it may (max_held) until one is released
  iteration_limit = 22,       // a loop ran its maximum of iterations or attempts without its condition met
  overrun = 23,               // a periodic loop's tick ended after its deadline
  refused = 24,               // the system refused a privilege asked for (a real-time priority, CPUs, locked memory)
};

constexpr std::string_view to_string(Errc code) noexcept {
  switch (code) {
    case Errc::timeout: return "timeout";
    case Errc::stopped: return "stopped";
    case Errc::no_data: return "no data";
    case Errc::overflow: return "overflow";
    case Errc::block_failed: return "block failed";
    case Errc::type_mismatch: return "type mismatch";
    case Errc::peer_dead: return "peer dead";
    case Errc::unreachable: return "unreachable";
    case Errc::in_use: return "in use";
    case Errc::qos_mismatch: return "QoS mismatch";
    case Errc::no_space: return "no space";
    case Errc::not_found: return "not found";
    case Errc::damaged: return "damaged";
    case Errc::invalid_argument: return "invalid argument";
    case Errc::too_large: return "too large";
    case Errc::queue_full: return "queue full";
    case Errc::too_many_subscribers: return "too many subscribers";
    case Errc::too_many_clients: return "too many clients";
    case Errc::domain_full: return "domain full";
    case Errc::rate_limited: return "rate limited";
    case Errc::held_limit: return "held limit";
    case Errc::iteration_limit: return "iteration limit";
    case Errc::overrun: return "overrun";
    case Errc::refused: return "refused";
  }
  return "unknown";
}

// The Errc whose value is `value`, if there is one: for codes read off a
// wire, so a code added here is accepted there without another edit.
constexpr std::optional<Errc> errc_from(int value) noexcept {
  const auto code = static_cast<Errc>(value);
  if (value < 0 || to_string(code) == "unknown") return std::nullopt;
  return code;
}

struct Error {
  Errc code;
  std::string message;  // names the endpoint and what was expected

  [[nodiscard]] std::string describe() const {
    return std::string{to_string(code)} + ": " + message;
  }
};

// The exception form of an Error, for setup mistakes and for chains, whose call
// operator returns a plain value and so can only fail by throwing.
class Failure : public std::runtime_error {
 public:
  explicit Failure(Error error) : std::runtime_error{error.describe()}, error_{std::move(error)} {}
  [[nodiscard]] const Error& error() const noexcept { return error_; }

 private:
  Error error_;
};

}  // namespace prime
