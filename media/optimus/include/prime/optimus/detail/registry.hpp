#pragma once

#include <cstdio>
#include <string>
#include <string_view>

#include "prime/common/fingerprint.hpp"
#include "prime/logic/error.hpp"
#include "prime/optimus/detail/connection.hpp"
#include "prime/optimus/detail/pool.hpp"

namespace prime::optimus::detail {

// "<hash> <description>": how a registry hash records an endpoint's types.
inline std::string type_record(const Fingerprint& in) {
  char hex[24];
  std::snprintf(hex, sizeof hex, "%016llx", static_cast<unsigned long long>(in.hash));
  return std::string{hex} + " " + in.describe();
}

// Records `record` for `name` in the registry hash `registry`, or throws
// Errc::type_mismatch when the name is already there with other types (a
// second process serving or publishing the same name with the same types is
// fine). `what` names the endpoint ("source 'lidar'").
inline void register_types(Pool& pool, const std::string& registry, const std::string& name,
                           const std::string& record, const std::string& what, bool write) {
  auto lease = pool.acquire();
  if (!lease) throw Failure{{lease.error().code, what + ": " + lease.error().message}};
  auto& c = **lease;
  c.set_timeout(std::chrono::duration_cast<std::chrono::microseconds>(pool.options().connect_timeout));
  auto existing = c.command({"HGET", registry, name});
  if (!existing) throw Failure{{existing.error().code, what + ": " + existing.error().message}};
  if (is_error(**existing)) throw Failure{server_error(**existing, what + ": reading the registry")};
  const auto mismatch = [&](std::string_view found) {
    return Failure{{Errc::type_mismatch, what + " is registered as " + std::string{found} + ", not as " + record}};
  };
  if (!is_nil(**existing) && text(**existing) != record) throw mismatch(text(**existing));
  if (!write || !is_nil(**existing)) return;
  // Set only if still unset: of two processes registering at once with
  // other types, the second learns of the first's.
  auto done = c.command({"HSETNX", registry, name, record});
  if (!done) throw Failure{{done.error().code, what + ": " + done.error().message}};
  if (is_error(**done)) throw Failure{server_error(**done, what + ": writing the registry")};
  if ((**done).integer() == 1) return;
  auto now = c.command({"HGET", registry, name});
  if (!now) throw Failure{{now.error().code, what + ": " + now.error().message}};
  if (!is_error(**now) && !is_nil(**now) && text(**now) != record) throw mismatch(text(**now));
}

}  // namespace prime::optimus::detail
