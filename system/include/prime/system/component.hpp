#pragma once

#include <array>
#include <chrono>
#include <cstdint>
#include <functional>
#include <optional>
#include <string>
#include <utility>
#include <variant>
#include <vector>

#include "prime/common/fingerprint.hpp"
#include "prime/logic/error.hpp"
#include "prime/topology/qos.hpp"
#include "prime/topology/sync.hpp"

namespace prime::system {

class Context;

// What a port is to the rest of the system.
enum class PortKind { publishes, subscribes, serves, calls };

constexpr std::string_view to_string(PortKind kind) noexcept {
  switch (kind) {
    case PortKind::publishes: return "publishes";
    case PortKind::subscribes: return "subscribes";
    case PortKind::serves: return "serves";
    case PortKind::calls: return "calls";
  }
  return "?";
}

// How a caller waits on a service, wherever it is served.
struct CallQos {
  std::chrono::milliseconds timeout{1000};           // per call
  std::chrono::milliseconds wait_for_service{1000};  // for a server not (yet) up, in another process
};

// One port: a topic (its message type) or a service (request and reply).
// `message` is the topic's type or the service's request; `reply` is set
// for services only. A topic's publisher sets its QoS (unless the system
// file does); a subscriber's sets its own buffer.
struct Port {
  PortKind kind;
  std::string name;
  Fingerprint message;
  std::optional<Fingerprint> reply{};
  Qos qos{};
  CallQos call{};
  // Whether the type may cross a process (trivially copyable): what
  // validation refuses for a placement that splits the link otherwise.
  bool crosses_processes = true;
};

// A parameter's value: what a system file and a command line can give.
using ParamValue = std::variant<bool, std::int64_t, double, std::string>;

// The kind of a parameter's value, with its article: "a bool", "an integer",
// "a number", "a string" (by the variant's index).
constexpr std::string_view param_type_name(std::size_t index) noexcept {
  constexpr std::string_view names[] = {"a bool", "an integer", "a number", "a string"};
  return index < 4 ? names[index] : "?";
}

struct Param {
  std::string name;
  ParamValue value;  // the default; its alternative is the parameter's type
  std::string help{};
};

// A periodic trigger the component runs: its name and default period (a
// parameter "<name>.period_ms" overrides it).
struct Trigger {
  std::string name;
  std::chrono::milliseconds period;
};

// A synchronised set: topics the component subscribes to, read together as
// one source of Synced tuples put together by `policy` (Context::synced).
struct SyncedSet {
  std::string name;
  std::vector<std::string> topics;
  std::vector<Fingerprint> messages;  // each topic's type, in order
  SyncPolicy policy;
};

// A component: plain functions and chains, with its ports, parameters and
// triggers declared as data. It names no medium: where each port leads is
// the placement's choice, made by the host (Host) that builds it.
//
//   const auto planner = prime::system::Component{"planner"}
//       .subscribes<Scan>("sensors/lidar", {.capacity = 16})
//       .calls<MotorCommand, Applied>("driver/command")
//       .syncs<Scan, Odometry>("sensed", {"sensors/lidar", "sensors/odom"}, prime::approximate_time())
//       .every("control", 20ms)
//       .param("gain", 2.0, "turn rate per radian of heading error")
//       .build([](prime::system::Context& ctx) { ... });
//
// `build` runs once per instance when its process starts: it takes its
// handles from the context (inputs, outputs, services, loops), links its
// chains and returns; what it starts runs until the host stops.
class Component {
 public:
  using Build = std::function<void(Context&)>;

  explicit Component(std::string type) : type_{std::move(type)} {}

  template <class T>
  Component publishes(std::string name, Qos qos = {}) && {
    return std::move(*this).add(topic<T>(PortKind::publishes, std::move(name), qos));
  }
  template <class T>
  Component subscribes(std::string name, Qos qos = {}) && {
    return std::move(*this).add(topic<T>(PortKind::subscribes, std::move(name), qos));
  }
  // A synchronised set of topics, each of which the component subscribes
  // to (with `qos`, unless it declared the topic before with its own).
  template <class... T>
    requires(sizeof...(T) >= 2)
  Component syncs(std::string name, std::array<std::string, sizeof...(T)> topics, SyncPolicy policy, Qos qos = {}) && {
    SyncedSet set{std::move(name), {topics.begin(), topics.end()}, {Fingerprint::of<T>()...}, policy};
    std::size_t i = 0;
    ((declare_subscription<T>(topics[i++], qos)), ...);
    sets_.push_back(std::move(set));
    return std::move(*this);
  }
  template <class In, class Out>
  Component serves(std::string name) && {
    return std::move(*this).add(service<In, Out>(PortKind::serves, std::move(name)));
  }
  template <class In, class Out>
  Component calls(std::string name, CallQos qos = {}) && {
    auto port = service<In, Out>(PortKind::calls, std::move(name));
    port.call = qos;
    return std::move(*this).add(std::move(port));
  }
  Component every(std::string name, std::chrono::milliseconds period) && {
    triggers_.push_back({std::move(name), period});
    return std::move(*this);
  }
  // A parameter of the default's type: bool, an integer, a number or a string.
  template <class V>
  Component param(std::string name, V value, std::string help = {}) && {
    params_.push_back({std::move(name), to_param(std::move(value)), std::move(help)});
    return std::move(*this);
  }
  Component build(Build build) && {
    build_ = std::move(build);
    return std::move(*this);
  }

  [[nodiscard]] const std::string& type() const noexcept { return type_; }
  [[nodiscard]] const std::vector<Port>& ports() const noexcept { return ports_; }
  [[nodiscard]] const std::vector<Param>& params() const noexcept { return params_; }
  [[nodiscard]] const std::vector<Trigger>& triggers() const noexcept { return triggers_; }
  [[nodiscard]] const std::vector<SyncedSet>& synced_sets() const noexcept { return sets_; }
  [[nodiscard]] const Build& builder() const noexcept { return build_; }

  [[nodiscard]] const Port* port(std::string_view name, PortKind kind) const noexcept {
    for (const auto& p : ports_)
      if (p.name == name && p.kind == kind) return &p;
    return nullptr;
  }
  [[nodiscard]] const Param* param(std::string_view name) const noexcept {
    for (const auto& p : params_)
      if (p.name == name) return &p;
    return nullptr;
  }
  [[nodiscard]] const SyncedSet* synced_set(std::string_view name) const noexcept {
    for (const auto& s : sets_)
      if (s.name == name) return &s;
    return nullptr;
  }
  [[nodiscard]] const Trigger* trigger(std::string_view name) const noexcept {
    for (const auto& t : triggers_)
      if (t.name == name) return &t;
    return nullptr;
  }

  template <class V>
  static ParamValue to_param(V value) {
    if constexpr (std::is_same_v<V, bool>) return value;
    else if constexpr (std::is_integral_v<V>) return static_cast<std::int64_t>(value);
    else if constexpr (std::is_floating_point_v<V>) return static_cast<double>(value);
    else return std::string{std::move(value)};
  }

 private:
  template <class T>
  static Port topic(PortKind kind, std::string name, const Qos& qos) {
    return {kind, std::move(name), Fingerprint::of<T>(), std::nullopt, qos, {}, std::is_trivially_copyable_v<T>};
  }
  template <class In, class Out>
  static Port service(PortKind kind, std::string name) {
    return {kind, std::move(name), Fingerprint::of<In>(), Fingerprint::of<Out>(), {}, {},
            std::is_trivially_copyable_v<In> && std::is_trivially_copyable_v<Out>};
  }
  // A topic of a synchronised set: declared here unless it was already, as
  // the same type (another type is the component's own mistake).
  template <class T>
  void declare_subscription(const std::string& name, const Qos& qos) {
    if (const auto* declared = port(name, PortKind::subscribes)) {
      if (!(declared->message == Fingerprint::of<T>()))
        throw Failure{{Errc::type_mismatch, "component '" + type_ + "': '" + name + "' is subscribed to as " +
                                                declared->message.describe() + " and synchronised as " +
                                                Fingerprint::of<T>().describe()}};
      return;
    }
    ports_.push_back(topic<T>(PortKind::subscribes, name, qos));
  }
  Component add(Port port) && {
    ports_.push_back(std::move(port));
    return std::move(*this);
  }

  std::string type_;
  std::vector<Port> ports_;
  std::vector<Param> params_;
  std::vector<Trigger> triggers_;
  std::vector<SyncedSet> sets_;
  Build build_;
};

}  // namespace prime::system
