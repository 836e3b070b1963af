#pragma once

#include <optional>
#include <stdexcept>
#include <string>
#include <string_view>

namespace prime {

// What went wrong on the data path. `stopped` (the owner shut down) is kept
// apart from the failures, so a worker can tell "leave now" from "report this".
enum class Errc {
  timeout,         // a deadline passed before a value arrived or room was made
  stopped,         // the core or worker that owns the endpoint is shutting down
  no_data,         // a reader was asked for a value none has published yet
  overflow,        // a value was dropped: a bounded buffer was full
  block_failed,    // a user's block threw; `message` carries what it said
  limit_exceeded,  // an iteration or size limit was crossed
  type_mismatch,   // an endpoint was opened with another type than it carries
  peer_dead,       // the process on the other side is gone
  unreachable,     // a server could not be reached
  in_use,          // a name that admits one owner (a topic's publisher) has a live one
  qos_mismatch,    // an endpoint exists with other QoS than this side asks for
  no_space,        // memory for an endpoint could not be reserved (a full /dev/shm)
  not_found,       // no endpoint of that name exists (a service nobody serves)
  damaged,         // bytes another process left (shared memory, a Redis entry) break their own bounds
};

constexpr std::string_view to_string(Errc code) noexcept {
  switch (code) {
    case Errc::timeout: return "timeout";
    case Errc::stopped: return "stopped";
    case Errc::no_data: return "no data";
    case Errc::overflow: return "overflow";
    case Errc::block_failed: return "block failed";
    case Errc::limit_exceeded: return "limit exceeded";
    case Errc::type_mismatch: return "type mismatch";
    case Errc::peer_dead: return "peer dead";
    case Errc::unreachable: return "unreachable";
    case Errc::in_use: return "in use";
    case Errc::qos_mismatch: return "QoS mismatch";
    case Errc::no_space: return "no space";
    case Errc::not_found: return "not found";
    case Errc::damaged: return "damaged";
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
