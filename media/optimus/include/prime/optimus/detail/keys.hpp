#pragma once

#include <chrono>
#include <cstdint>
#include <cstdio>
#include <optional>
#include <string>
#include <string_view>

#include "prime/optimus/detail/escape.hpp"

namespace prime::optimus::detail {

// The keys of one domain: "<domain>:<kind>:<escaped name>"; nothing else is
// ever touched. The domain goes in as it is, so that it can be an ACL's key
// pattern ("~robot:*").
inline std::string domain_key(std::string_view domain, std::string_view kind, std::string_view name) {
  std::string k;
  k.reserve(domain.size() + kind.size() + name.size() + 2);
  return k.append(domain).append(":").append(kind).append(":").append(escaped(name));
}
inline std::string service_key(std::string_view domain, std::string_view name) { return domain_key(domain, "svc", name); }
// Kept by the core hosting a service while it lives (beside its request key).
inline std::string alive_key(std::string_view request_key) { return std::string{request_key} + ":alive"; }
inline std::string services_key(std::string_view domain) { return domain_key(domain, "registry", "services"); }
inline std::string sources_key(std::string_view domain) { return domain_key(domain, "registry", "sources"); }
inline std::string stream_key(std::string_view domain, std::string_view name) { return domain_key(domain, "src", name); }
inline std::string readers_key(std::string_view domain, std::string_view name) { return domain_key(domain, "readers", name); }
// One call's: "<domain>:reply:<process id>:<n>". A process id (Pool) is
// "<pid>.<hex>", so it needs no escaping.
inline std::string reply_key(std::string_view domain, std::string_view process_id, std::uint64_t id) {
  return std::string{domain}.append(":reply:").append(process_id).append(":").append(std::to_string(id));
}
// One worker's, that a stop pushes to: "<domain>:wake:<process id>:<n>".
inline std::string wake_key(std::string_view domain, std::string_view process_id, std::uint64_t n) {
  return std::string{domain}.append(":wake:").append(process_id).append(":").append(std::to_string(n));
}

// Whether `key` is one a caller of `domain` waits on for its answer (the
// shape reply_key() makes): the only keys a worker answers to.
inline bool is_reply_key(std::string_view domain, std::string_view key) {
  const auto prefix = std::string{domain} + ":reply:";
  if (!key.starts_with(prefix)) return false;
  // <digits>.<hex>:<digits>
  const auto rest = key.substr(prefix.size());
  const auto dot = rest.find('.');
  const auto colon = rest.find(':');
  const auto all = [](std::string_view s, auto ok) {
    if (s.empty()) return false;
    for (const char c : s)
      if (!ok(c)) return false;
    return true;
  };
  const auto digit = [](char c) { return c >= '0' && c <= '9'; };
  const auto hex = [&](char c) { return digit(c) || (c >= 'a' && c <= 'f'); };
  return dot != std::string_view::npos && colon != std::string_view::npos && dot < colon &&
         all(rest.substr(0, dot), digit) && all(rest.substr(dot + 1, colon - dot - 1), hex) &&
         all(rest.substr(colon + 1), digit);
}

// The name of the service whose request key in `domain` is `key`; null when
// `key` is not one (the only keys a linked call hands on to).
inline std::optional<std::string> service_name(std::string_view domain, std::string_view key) {
  const auto prefix = service_key(domain, "");
  if (!key.starts_with(prefix)) return std::nullopt;
  const auto rest = key.substr(prefix.size());
  auto name = unescaped(rest);
  if (!name || escaped(*name) != rest) return std::nullopt;  // only the one spelling service_key() makes
  return name;
}

// A key from a request, as an error message shows it: quoted, and cut short.
inline std::string shown_key(std::string_view key) {
  constexpr std::size_t kShown = 200;
  return "'" + std::string{key.substr(0, kShown)} + (key.size() > kShown ? "'..." : "'");
}

// A service's liveness: refreshed by its hosting core, gone this long after the last such core died.
inline constexpr std::chrono::milliseconds kAliveFor{3000};
inline constexpr std::chrono::milliseconds kAliveRefresh{1000};
// How long a request or an answer stays on the server past its call's
// deadline, if nobody takes it (its caller was killed, or gave up; its
// service's process died): a margin for the clocks of the caller, the
// worker and the server, which agree only to within a round trip.
inline constexpr std::chrono::milliseconds kUntakenFor{10'000};
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
