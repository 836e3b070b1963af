#pragma once

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cstdint>
#include <deque>
#include <memory>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/optimus/options.hpp"

namespace prime::optimus {

// Looking at an Optimus domain from outside, for tools: what its registry
// lists, how long each source's stream is, who reads it, which services
// are alive, and the entries a source appends from now on. Nothing here
// registers, reads as a reader or takes a request.

struct SourceSummary {
  std::string name;
  std::string type;           // its type, as the registry describes it
  std::string stream;         // the stream's key
  long long length = 0;       // entries in the stream now
  long long readers = 0;      // readers registered (live leases)
  std::string record;         // its type as the registry keeps it: "<hash> <description>"
};

struct ServiceSummary {
  std::string name;
  std::string types;  // request and reply, as the registry describes them
  bool alive = false;  // a server refreshed its alive key lately
};

// An entry of a source's stream.
struct StreamEntry {
  std::optional<std::uint64_t> sequence{};       // none in an entry not Prime's
  std::optional<Clock::time_point> stamp{};      // its sensor's; none in an entry not Prime's
  std::string data{};                            // the message's bytes
};

namespace detail {
class Connection;  // detail/connection.hpp
class ReplyRef;    // detail/reply.hpp
}  // namespace detail

// One connection to the server of `options` (its URL, credentials and
// connect timeout), looking at domain `options.domain`. Each call throws
// Failure: Errc::unreachable (the server, or a reply it refused).
// Compiled in libprime_optimus (src/inspect.cpp).
class Inspector {
 public:
  explicit Inspector(Options options);
  Inspector(Inspector&&) noexcept;
  Inspector& operator=(Inspector&&) noexcept;
  ~Inspector();

  // The server as errors show it: its URL without a password.
  [[nodiscard]] std::string server() const;

  [[nodiscard]] std::vector<SourceSummary> sources();
  [[nodiscard]] std::vector<ServiceSummary> services();

  // The entries appended to a source's stream from when it is made, one
  // at a time (read a hundred at a time). Lives no longer than its Inspector.
  class Tail {
   public:
    // The next entry, waiting for it up to `timeout`.
    std::optional<StreamEntry> next(Clock::duration timeout);

   private:
    friend class Inspector;
    Tail(Inspector& inspector, std::string stream, std::string from)
        : inspector_{&inspector}, stream_{std::move(stream)}, last_{std::move(from)} {}

    // [stream, [[id, [field, value, ...]], ...]]: checked, since another
    // process wrote it.
    void read(detail::ReplyRef stream);

    Inspector* inspector_;
    std::string stream_;
    std::string last_;  // the id of the last entry read (or of the newest when it was made)
    std::deque<StreamEntry> buffered_;
  };

  [[nodiscard]] Tail tail(const std::string& source);

 private:
  Options options_;
  std::unique_ptr<detail::Connection> connection_;
};

}  // namespace prime::optimus
