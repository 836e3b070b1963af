#pragma once

#include <concepts>
#include <expected>
#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <type_traits>
#include <utility>
#include <variant>

#include "prime/logic/error.hpp"
#include "prime/system/component.hpp"
#include "prime/system/detail/links.hpp"
#include "prime/system/input.hpp"
#include "prime/topology/local_source.hpp"
#include "prime/topology/loop.hpp"

namespace prime::system {

namespace detail {

// What may cross a process (and a machine): trivially copyable messages,
// as Shm carries them and Optimus sends them as bytes. Other types link
// components in one process only.
template <class T>
concept Crosses = shm::Message<T>;

// A medium's publisher of T where T may cross, else nothing (named only
// when chosen: the publishers refuse other types).
template <class T>
struct ShmPublisherOf {
  using type = std::optional<shm::Publisher<T>>;
};
template <class T>
struct OptimusPublisherOf {
  using type = std::optional<optimus::Publisher<T>>;
};
template <class T>
using ShmPublisher = typename std::conditional_t<Crosses<T>, ShmPublisherOf<T>, std::type_identity<std::monostate>>::type;
template <class T>
using OptimusPublisher = typename std::conditional_t<Crosses<T>, OptimusPublisherOf<T>, std::type_identity<std::monostate>>::type;

// A service served in this process, called directly by its in-process
// clients: one call at a time, as one worker serves it in another process.
template <class In, class Out>
struct LocalService {
  std::mutex mutex;
  std::function<Out(const In&)> block;
};

[[noreturn]] inline void refuse(Errc code, const std::string& what) { throw Failure{{code, what}}; }

}  // namespace detail

// The writing end of a topic a component publishes: to its readers in
// this process (the value itself, never serialised: moved to one reader of
// values, copied for each further one, and one immutable copy for all the
// readers that share it), and through Shm or Optimus to those elsewhere,
// as the placement links it. Used by one thread at a time, as a medium's
// publisher is.
template <class T>
class Output {
 public:
  // Every end gets the value; the first medium that fails is the error
  // (the others still got it).
  std::expected<void, Error> publish(T value, Clock::time_point stamp = Clock::now()) const {
    std::expected<void, Error> result{};
    if constexpr (detail::Crosses<T>)
      if (state_->shm)
        if (auto sent = state_->shm->publish(value, stamp); !sent && result) result = std::unexpected(sent.error());
    if constexpr (detail::Crosses<T>)
      if (state_->optimus)
        if (auto sent = state_->optimus->publish(value, stamp); !sent && result) result = std::unexpected(sent.error());
    if (state_->local) publish_here(std::move(value), stamp);
    return result;
  }

  [[nodiscard]] const std::string& name() const noexcept { return state_->name; }

 private:
  friend class Context;
  struct State {
    std::string name;
    std::optional<LocalSource<T>> local;                     // readers of values
    std::optional<LocalSource<std::shared_ptr<const T>>> shared;  // readers sharing one
    detail::ShmPublisher<T> shm;
    detail::OptimusPublisher<T> optimus;
  };
  explicit Output(std::shared_ptr<State> state) : state_{std::move(state)} {}

  void publish_here(T&& value, Clock::time_point stamp) const {
    if (state_->shared->readers() == 0) return state_->local->publish(std::move(value), stamp);
    std::shared_ptr<const T> one;
    if constexpr (std::copy_constructible<T>) {
      if (state_->local->readers() > 0) {
        one = std::make_shared<const T>(value);
        state_->local->publish(std::move(value), stamp);
      }
    }
    if (!one) one = std::make_shared<const T>(std::move(value));
    state_->shared->publish(std::move(one), stamp);
  }

  std::shared_ptr<State> state_;
};

// A component's hold on a service it calls, wherever it is served.
// Thread-safe.
template <class In, class Out>
class Client {
 public:
  using input_type = In;
  using output_type = Out;

  std::expected<Out, Error> call(const In& in) const { return call_(in); }

  [[nodiscard]] const std::string& name() const noexcept { return *name_; }

 private:
  friend class Context;
  Client(std::string name, std::function<std::expected<Out, Error>(const In&)> call)
      : name_{std::make_shared<const std::string>(std::move(name))}, call_{std::move(call)} {}
  std::shared_ptr<const std::string> name_;
  std::function<std::expected<Out, Error>(const In&)> call_;
};

// What a component's build gets: its parameters, and handles to its ports
// that name no medium. Each handle is checked against the component's
// declaration: a port it did not declare, or declared with another type,
// throws Errc::invalid_argument or Errc::type_mismatch naming both.
class Context {
 public:
  Context(const Component& component, const Instance& instance, detail::Links& links)
      : component_{component}, instance_{instance}, links_{links} {}

  // The instance's name ("planner"), as the system file gives it.
  [[nodiscard]] const std::string& name() const noexcept { return instance_.name; }
  [[nodiscard]] const std::string& process() const noexcept { return links_.plan.process; }

  // The parameter's value: the system file's (or the command line's), else
  // the declared default. V is the declared type: bool, an integer type, a
  // floating-point type or std::string.
  template <class V>
  [[nodiscard]] V param(const std::string& name) const {
    const auto* declared = component_.param(name);
    if (!declared) detail::refuse(Errc::invalid_argument, where() + ": no parameter '" + name + "' is declared");
    const auto found = instance_.params.find(name);
    const ParamValue& value = found == instance_.params.end() ? declared->value : found->second;
    using Stored = std::conditional_t<std::is_same_v<V, bool>, bool,
                   std::conditional_t<std::is_integral_v<V>, std::int64_t,
                   std::conditional_t<std::is_floating_point_v<V>, double, std::string>>>;
    if (const auto* v = std::get_if<Stored>(&value)) {
      if constexpr (std::is_integral_v<V> && !std::is_same_v<V, bool>)
        if (!std::in_range<V>(*v))
          detail::refuse(Errc::invalid_argument, where() + ": parameter '" + name + "' is " + std::to_string(*v) +
                                                     ", out of the range of the type it is read as");
      return static_cast<V>(*v);
    }
    detail::refuse(Errc::type_mismatch, where() + ": parameter '" + name + "' is " +
                                            std::string{param_type_name(value.index())} + ", read as another type");
  }

  // The topic the component publishes as `port`.
  template <class T>
  [[nodiscard]] Output<T> output(const std::string& port) {
    const auto& declared = check<T>(port, PortKind::publishes);
    using State = typename Output<T>::State;
    auto state = std::make_shared<State>();
    state->name = port;
    const auto reach = links_.reach(port);
    const auto qos = links_.topic_qos(port, declared.qos);
    if (reach & Reach::here) {
      state->local = hub<T>(port, qos);
      state->shared = shared_hub<T>(port, qos);
    }
    if (reach & Reach::same_machine) {
      if constexpr (detail::Crosses<T>) state->shm.emplace(links_.shm->publisher<T>(links_.wire_name(port), shm_qos(qos)));
      else cannot_cross<T>(port, "another process");
    }
    if (reach & Reach::other_machine) {
      if constexpr (detail::Crosses<T>) state->optimus.emplace(links_.optimus->publisher<T>(links_.wire_name(port), qos));
      else cannot_cross<T>(port, "another machine");
    }
    return Output<T>{std::move(state)};
  }

  // The topic the component subscribes to as `port` (see Input), read
  // where the placement put its publisher: each reader gets a value of its
  // own (copied out of shared memory as it is read).
  template <class T>
  [[nodiscard]] Input<T> input(const std::string& port) {
    return open_input<T, false>(port);
  }
  // The same topic with every reader sharing one immutable value, never
  // copied: one made by the publisher in this process, the sample in place
  // in shared memory from another process (holding its slot for as long as
  // a copy of the pointer lives: keep few), or the one received from Redis.
  template <class T>
    requires std::copy_constructible<T>
  [[nodiscard]] Input<std::shared_ptr<const T>> shared_input(const std::string& port) {
    return open_input<T, true>(port);
  }

  // The declared synchronised set `name`: a source of Synced<T...>, one
  // value of each of its topics per set, as its policy puts them together
  // (prime::sync over this component's inputs of them).
  template <class... T>
  [[nodiscard]] auto synced(const std::string& name) {
    const auto* set = component_.synced_set(name);
    if (!set) detail::refuse(Errc::invalid_argument, where() + ": it declares no synchronised set '" + name + "'");
    const std::vector<Fingerprint> used{Fingerprint::of<T>()...};
    if (used != set->messages) {
      std::string declared, as;
      for (const auto& f : set->messages) declared += (declared.empty() ? "" : ", ") + f.describe();
      for (const auto& f : used) as += (as.empty() ? "" : ", ") + f.describe();
      detail::refuse(Errc::type_mismatch, where() + ": synchronised set '" + name + "' is declared as (" + declared +
                                              "), used as (" + as + ")");
    }
    return [&]<std::size_t... I>(std::index_sequence<I...>) {
      return prime::sync(set->policy, input<T>(set->topics[I])...);
    }(std::index_sequence_for<T...>{});
  }

  // Serves `block` (any callable or chain taking `const In&`, giving Out)
  // as the service `port`: called directly by clients in this process, and
  // through Shm or Optimus by those elsewhere. What it throws is the
  // caller's error.
  template <class In, class Out, class F>
  void serve(const std::string& port, F block) {
    check<In, Out>(port, PortKind::serves);
    auto service = std::make_shared<detail::LocalService<In, Out>>();
    service->block = std::function<Out(const In&)>{std::move(block)};
    const auto reach = links_.reach(port);
    const auto run = [service](const In& in) -> Out {
      std::scoped_lock lock{service->mutex};
      return service->block(in);
    };
    if (reach & Reach::same_machine) {
      if constexpr (detail::Crosses<In> && detail::Crosses<Out>) links_.kept.emplace_back(links_.shm->serve<In>(links_.wire_name(port), run));
      else cannot_cross<In>(port, "another process");
    }
    if (reach & Reach::other_machine) {
      if constexpr (detail::Crosses<In> && detail::Crosses<Out>) links_.kept.emplace_back(links_.optimus->serve<In>(links_.wire_name(port), run));
      else cannot_cross<In>(port, "another machine");
    }
    std::scoped_lock lock{links_.mutex};
    if (!links_.services.emplace(port, service).second)
      detail::refuse(Errc::in_use, where() + ": service '" + port + "' is served twice in process '" + process() + "'");
  }

  // The service the component calls as `port`, wherever it is served.
  // A call fails as the medium's does: Errc::not_found with no server,
  // Errc::timeout past the port's timeout, Errc::block_failed with what the
  // server's block threw.
  template <class In, class Out>
  [[nodiscard]] Client<In, Out> client(const std::string& port) {
    const auto& declared = check<In, Out>(port, PortKind::calls);
    const auto reach = links_.reach(port);
    const auto wire = links_.wire_name(port);
    if (reach & Reach::here) {
      // served in this process: called directly, below
    } else if (reach & Reach::same_machine) {
      if constexpr (detail::Crosses<In> && detail::Crosses<Out>) {
        auto chain = links_.shm->chain<In, Out>(wire, {.timeout = declared.call.timeout, .wait_for_service = declared.call.wait_for_service});
        return {port, [chain](const In& in) { return chain.call(in); }};
      } else {
        cannot_cross<In>(port, "another process");
      }
    } else if (reach & Reach::other_machine) {
      if constexpr (detail::Crosses<In> && detail::Crosses<Out>) {
        auto chain = links_.optimus->service<In, Out>(wire, {.timeout = declared.call.timeout});
        return {port, [chain](const In& in) { return chain.call(in); }};
      } else {
        cannot_cross<In>(port, "another machine");
      }
    }
    auto lookup = [links = &links_, port]() -> std::shared_ptr<detail::LocalService<In, Out>> {
      std::scoped_lock lock{links->mutex};
      const auto found = links->services.find(port);
      if (found == links->services.end()) return nullptr;
      auto* typed = std::any_cast<std::shared_ptr<detail::LocalService<In, Out>>>(&found->second);
      return typed ? *typed : nullptr;
    };
    return {port, [lookup, port, process = process()](const In& in) -> std::expected<Out, Error> {
              const auto service = lookup();
              if (!service)
                return std::unexpected(Error{Errc::not_found, "service '" + port + "': not served in process '" + process +
                                                                  "' with these types"});
              try {
                std::scoped_lock lock{service->mutex};
                return service->block(in);
              } catch (const std::exception& e) {
                return std::unexpected(Error{Errc::block_failed, "service '" + port + "': " + e.what()});
              }
            }};
  }

  // Runs `chain` on the declared trigger `name`'s period (the parameter
  // "<name>.period_ms" overrides it), as prime::every does, until the host
  // stops. With a link to another process, the loop is shown by `prime ls`.
  template <class C>
    requires std::invocable<C&, Token>
  Loop& every(const std::string& name, C chain, LoopOptions options = {}) {
    const auto* declared = component_.trigger(name);
    if (!declared) detail::refuse(Errc::invalid_argument, where() + ": no trigger '" + name + "' is declared");
    std::chrono::milliseconds period = declared->period;
    if (const auto found = instance_.params.find(name + ".period_ms"); found != instance_.params.end()) {
      const auto* ms = std::get_if<std::int64_t>(&found->second);
      if (!ms) detail::refuse(Errc::type_mismatch, where() + ": parameter '" + name + ".period_ms' must be an integer");
      period = std::chrono::milliseconds{*ms};
    }
    if (options.name == LoopOptions{}.name) options.name = instance_.name + "/" + name;
    auto loop = links_.shm ? prime::every(*links_.shm, period, std::move(chain), std::move(options))
                           : prime::every(links_.local, period, std::move(chain), std::move(options));
    std::scoped_lock lock{links_.mutex};
    return links_.loops.emplace_back(std::move(loop));
  }

  // This process's core for chains, syncs and collectors of the component.
  [[nodiscard]] liberty::Core& local() noexcept { return links_.local; }

 private:
  std::string where() const { return "component '" + instance_.name + "' (" + component_.type() + ")"; }

  template <class T, bool Shared>
  auto open_input(const std::string& port) {
    using V = std::conditional_t<Shared, std::shared_ptr<const T>, T>;
    const auto& declared = check<T>(port, PortKind::subscribes);
    const auto reach = links_.reach(port);
    const auto fed = fed_input<T>(port);
    const auto reader_qos = fed ? fed->qos : declared.qos;
    const auto here = [&](const Qos& topic_qos) -> typename Input<V>::Open {
      if constexpr (Shared) return [local = shared_hub<T>(port, topic_qos)](const Qos& qos) { return local.subscribe(qos); };
      else return [local = hub<T>(port, topic_qos)](const Qos& qos) { return local.subscribe(qos); };
    };
    typename Input<V>::Open open;
    std::string medium = "local";
    if (fed) {
      if constexpr (Shared) open = [from = fed->open](const Qos& qos) { return detail::shared_values<T>(from(qos)); };
      else open = fed->open;
      medium = "fed";
    } else if (reach & Reach::here) {
      open = here(links_.topic_qos(port, declared.qos));
    } else if (reach & Reach::same_machine) {
      if constexpr (detail::Crosses<T>) {
        auto topic = links_.shm->subscribe<T>(links_.wire_name(port), {.spin = std::chrono::duration_cast<std::chrono::microseconds>(reader_qos.spin)},
                                              shm_qos(links_.topic_qos(port, declared.qos)));
        if constexpr (Shared) open = [topic](const Qos&) { return detail::shared_in_place<T>(topic.subscribe()); };
        else open = [topic](const Qos&) { return detail::copied_out<T>(topic.subscribe()); };
        medium = "shm";
      } else {
        cannot_cross<T>(port, "another process");
      }
    } else if (reach & Reach::other_machine) {
      if constexpr (detail::Crosses<T>) {
        auto topic = links_.optimus->subscribe<T>(links_.wire_name(port), reader_qos);
        if constexpr (Shared) open = [topic](const Qos&) { return detail::shared_values<T>(topic.subscribe()); };
        else open = [topic](const Qos&) { return topic.subscribe(); };
        medium = "optimus";
      } else {
        cannot_cross<T>(port, "another machine");
      }
    } else {  // nobody publishes it: an input that stays empty
      open = here(declared.qos);
    }
    return Input<V>{port, reader_qos, links_.local.runtime(), Graph::node(port, "source", medium), std::move(open)};
  }

  template <class T>
  const Port& check(const std::string& port, PortKind kind) {
    const auto* declared = component_.port(port, kind);
    if (!declared)
      detail::refuse(Errc::invalid_argument, where() + ": it does not declare that it " + std::string{to_string(kind)} + " '" + port + "'");
    if (!(declared->message == Fingerprint::of<T>()))
      detail::refuse(Errc::type_mismatch, where() + ": '" + port + "' is declared as " + declared->message.describe() +
                                              ", used as " + Fingerprint::of<T>().describe());
    return *declared;
  }
  template <class In, class Out>
  const Port& check(const std::string& port, PortKind kind) {
    const auto& declared = check<In>(port, kind);
    if (!(declared.reply && *declared.reply == Fingerprint::of<Out>()))
      detail::refuse(Errc::type_mismatch, where() + ": '" + port + "' replies " +
                                              (declared.reply ? declared.reply->describe() : "nothing") + ", used as " +
                                              Fingerprint::of<Out>().describe());
    return declared;
  }

  template <class T>
  [[noreturn]] void cannot_cross(const std::string& port, const char* to) {
    detail::refuse(Errc::invalid_argument, where() + ": '" + port + "' carries " + Fingerprint::of<T>().describe() +
                                               ", which cannot be sent to " + to +
                                               " (a message crossing processes is trivially copyable): place its ends in one process");
  }

  template <class Want>
  Want typed(const std::any& held, const std::string& port) {
    if (const auto* typed = std::any_cast<Want>(&held)) return *typed;
    detail::refuse(Errc::type_mismatch, where() + ": '" + port + "' is carried in this process with another type");
  }

  // The input's source when the host's owner gives it (a test playing a recording).
  template <class T>
  std::optional<detail::FedInput<T>> fed_input(const std::string& port) {
    std::scoped_lock lock{links_.mutex};
    const auto found = links_.fed.find(port);
    if (found == links_.fed.end()) return std::nullopt;
    return typed<detail::FedInput<T>>(found->second, port);
  }

  // The in-process end of the topic, for readers of values (hub) or of
  // shared values (shared_hub): made by whichever of its ends comes first.
  template <class T>
  LocalSource<T> hub(const std::string& port, const Qos& qos) {
    return local_end<T>(links_.topics, port, qos);
  }
  template <class T>
  LocalSource<std::shared_ptr<const T>> shared_hub(const std::string& port, const Qos& qos) {
    return local_end<std::shared_ptr<const T>>(links_.shared, port, qos);
  }
  template <class V>
  LocalSource<V> local_end(std::map<std::string, std::any>& ends, const std::string& port, const Qos& qos) {
    std::scoped_lock lock{links_.mutex};
    if (const auto found = ends.find(port); found != ends.end()) return typed<LocalSource<V>>(found->second, port);
    LocalSource<V> local{port, qos, links_.local.runtime(), Graph::node(port, "source", "local")};
    ends.emplace(port, local);
    return local;
  }

  static shm::TopicQos shm_qos(const Qos& qos) {
    return {.capacity = qos.capacity, .overflow = qos.overflow, .block_timeout = qos.block_timeout};
  }

  friend class Harness;  // gives inputs their sources (feed_from)

  const Component& component_;
  const Instance& instance_;
  detail::Links& links_;
};

}  // namespace prime::system
