#pragma once

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <string>
#include <string_view>

#include "prime/optimus/detail/pool.hpp"

namespace prime::optimus::detail {

// The keys of one domain ("<domain>:..."); nothing else is ever touched.
inline std::string service_key(const Pool& pool, std::string_view name) { return pool.key("svc:", name); }
// Kept by the core hosting a service while it lives (beside its request key).
inline std::string alive_key(std::string_view request_key) { return std::string{request_key} + ":alive"; }
inline std::string services_key(const Pool& pool) { return pool.key("registry:", "services"); }
inline std::string sources_key(const Pool& pool) { return pool.key("registry:", "sources"); }
inline std::string stream_key(const Pool& pool, std::string_view name) { return pool.key("src:", name); }
inline std::string readers_key(const Pool& pool, std::string_view name) { return pool.key("readers:", name); }
inline std::string reply_key(const Pool& pool, std::uint64_t id) {
  return pool.key("reply:", pool.process_id() + ":" + std::to_string(id));
}

// A service's liveness: refreshed by its hosting core, gone this long after the last such core died.
inline constexpr std::chrono::milliseconds kAliveFor{3000};
inline constexpr std::chrono::milliseconds kAliveRefresh{1000};
// How long one blocking wait of a worker lasts before it looks around (a
// refresh, a reconnect); a stop request ends it at once.
inline constexpr std::chrono::milliseconds kWaitSlice{1000};
// How long a worker whose wait the server refused waits before it asks
// again: doubling from the first to the most.
inline constexpr std::chrono::milliseconds kFirstRefusedBackoff{50};
inline constexpr std::chrono::milliseconds kMaxRefusedBackoff{1000};
// Extra time a socket read is allowed beyond the server-side block.
inline constexpr std::chrono::milliseconds kSocketMargin{1000};

inline std::string seconds_text(std::chrono::microseconds d) {
  if (d < std::chrono::microseconds{1000}) d = std::chrono::microseconds{1000};  // 0 would block forever
  char buffer[32];
  const int n = std::snprintf(buffer, sizeof buffer, "%.3f", static_cast<double>(d.count()) / 1e6);
  return {buffer, static_cast<std::size_t>(n)};
}

}  // namespace prime::optimus::detail
