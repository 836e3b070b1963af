#pragma once

#include <chrono>
#include <exception>
#include <expected>
#include <functional>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>
#include <string>
#include <string_view>
#include <type_traits>
#include <utility>

#include "prime/common/fingerprint.hpp"
#include "prime/logic/block.hpp"
#include "prime/logic/error.hpp"
#include "prime/logic/event.hpp"
#include "prime/optimus/chain.hpp"
#include "prime/optimus/codec.hpp"
#include "prime/optimus/options.hpp"
#include "prime/optimus/raw_publisher.hpp"
#include "prime/optimus/source.hpp"
#include "prime/optimus/stream.hpp"
#include "prime/topology/chain_factory.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/link.hpp"
#include "prime/topology/runtime.hpp"

namespace prime::optimus {

namespace detail {
// A service's block on an encoded request: the encoded result, or the error
// to send back. An exception from the block becomes an error; a
// prime::Failure keeps its code and message.
template <class In, class F>
std::expected<std::string, Error> run_block(const F& block, std::string_view payload, const std::string& where) {
  auto in = decode_message<In>(payload, where + ", request");
  if (!in) return std::unexpected(std::move(in.error()));
  try {
    return encode_message(std::invoke(block, std::move(*in)));
  } catch (const Failure& f) {
    return std::unexpected(f.error());
  } catch (const std::exception& e) {
    return std::unexpected(Error{Errc::block_failed, where + ": " + e.what()});
  } catch (...) {
    return std::unexpected(Error{Errc::block_failed, where + ": an exception of unknown type"});
  }
}

// What a service's workers run on each request: its block, on bytes.
using Handler = std::function<std::expected<std::string, Error>(std::string_view payload)>;
}  // namespace detail

// Redis as a medium, for systems that span machines. A chain's blocks are
// services: worker threads that wait on a request key, run the block and
// send the result on. Sources are bounded Redis streams. Every key lives
// under "<domain>:"; nothing is ever flushed.
//
//   prime::optimus::Core core{"tcp://10.0.0.2:6379"};
//   auto plan  = core.serve("planner", Planner{});                 // host a named service
//   auto remote = core.service<Pose, Path>("planner", {.timeout = 20ms});  // call one hosted anywhere
//   auto scans = core.subscribe<Scan>("lidar/scan");               // a source published anywhere
//
// Thread-safe. Destroying the core stops and joins its services' workers.
class Core : public Runtime, public ChainFactory<Core> {
 public:
  // Connects once to check the server: throws Errc::unreachable naming the URL.
  explicit Core(std::string url) : Core{Options{.url = std::move(url)}} {}
  explicit Core(Options options);
  Core(const Core&) = delete;
  Core& operator=(const Core&) = delete;
  ~Core();  // stops first: workers use what the members hold
  using ChainFactory<Core>::chain;

  // Stops and joins every worker of this core (its services, linked
  // sources). Chain calls waiting meanwhile end with Errc::stopped: a worker
  // may be waiting on a service that is stopping too. Idempotent.
  void stop();

  // A chain of one block, hosted as a service of this process (one worker)
  // and called through the server.
  template <class In = prime::detail::Deduce, class F>
  [[nodiscard]] auto chain(F block, Graph graph) {
    using I = chain_input_t<In, F>;
    static_assert(Block<F, I>, "prime::optimus: a block must be callable as Out(In) and return a value");
    using O = block_output_t<F, I>;
    std::string shown = display_name(graph);
    std::string name = private_name();
    host(name, shown, handler<I>(std::move(block), shown), ServeOptions{});
    return Chain<I, O>{{segment(name, std::move(shown))}, std::move(graph), options_.call_timeout};
  }
  // Hosts `block` (or a chain of any medium) as the service `name`, for any
  // process of the domain to call, and returns a chain that calls it. Several
  // processes may serve one name with the same types (they share the work);
  // other types under a taken name throw Errc::type_mismatch.
  template <class In = prime::detail::Deduce, class F>
  auto serve(std::string name, F block, ServeOptions serve_options = {}) {
    using I = chain_input_t<In, F>;
    static_assert(Block<F, I>, "prime::optimus: a block must be callable as Out(In) and return a value");
    using O = block_output_t<F, I>;
    register_service(name, record<I, O>(), true);
    host(name, name, handler<I>(std::move(block), name), serve_options);
    return service<I, O>(name, {.timeout = options_.call_timeout});
  }

  // A chain that calls the service `name`, hosted by this process or any
  // other. Throws Errc::type_mismatch when the service is registered with
  // other types; a service not (yet) running is an error of each call.
  template <class In, class Out>
  [[nodiscard]] Chain<In, Out> service(std::string name, CallOptions call = {}) {
    register_service(name, record<In, Out>(), false);
    Graph graph = Graph::node(name, "service", "optimus");
    return Chain<In, Out>{{segment(name, name)}, std::move(graph), call.timeout};
  }

  // A source of what `event` raises from now on, carried by a stream: each
  // emit appends to it (one round trip) before it returns.
  template <class T>
  [[nodiscard]] Source<T> source(Event<T>& event, std::string name = "source", Qos qos = {}) {
    auto stream = open_stream(name, qos, Fingerprint::of<T>(), true);
    stream.feed_from(event.connect([weak = std::weak_ptr<detail::StreamState>{stream.state()}](Sample<T>&& s) {
      auto state = weak.lock();
      if (!state) return;
      const detail::Stream stream{std::move(state)};
      if (auto done = stream.publish(encode_message(s.value), s.stamp); !done) stream.report(done.error());
    }));
    return Source<T>{std::move(stream), Graph::node(std::move(name), "source", "optimus")};
  }

  // The writing end of the named source, for any process of the domain to read.
  template <class T>
  [[nodiscard]] Publisher<T> publisher(std::string name, Qos qos = {}) {
    auto stream = open_stream(name, qos, Fingerprint::of<T>(), true);
    return Publisher<T>{Source<T>{std::move(stream), Graph::node(std::move(name), "source", "optimus")}};
  }

  // The named source, published by this process or any other. `qos` is this
  // side's: the capacity of its readers.
  template <class T>
  [[nodiscard]] Source<T> subscribe(std::string name, Qos qos = {}) {
    auto stream = open_stream(name, qos, Fingerprint::of<T>(), false);
    return Source<T>{std::move(stream), Graph::node(std::move(name), "source", "optimus")};
  }

  // For tools (prime play): the writing end of the named source, of the
  // type registered as `record` ("<hash> <description>", as the registry
  // and Inspector::sources() give it), for messages that come encoded
  // (RawPublisher). Throws Errc::invalid_argument when `record` does not
  // start with a fingerprint hash, and Errc::type_mismatch when the
  // registry records the source with another type.
  [[nodiscard]] RawPublisher raw_publisher(const std::string& name, const std::string& record, Qos qos = {});

  [[nodiscard]] const Options& options() const noexcept { return options_; }
  // The server's URL, with the password it may carry as "***".
  [[nodiscard]] const std::string& url() const noexcept;

 private:
  template <class I, class O>
  static std::string record() {
    return type_record(Fingerprint::of<I>()) + " -> " + type_record(Fingerprint::of<O>());
  }
  // "<hash> <description>": how the registry records a type.
  static std::string type_record(const Fingerprint& type);

  template <class I, class F>
  static detail::Handler handler(F block, std::string shown) {
    return [shared = std::make_shared<const F>(std::move(block)), where = "service '" + std::move(shown) + "'"](
               std::string_view payload) { return detail::run_block<I>(*shared, payload, where); };
  }

  static std::string display_name(const Graph& graph) {
    std::string names = prime::detail::exit_names(graph);
    return names.empty() ? std::string{"chain"} : names;
  }

  // Records a service's types in the domain's registry (`write`: as its
  // server), or throws Errc::type_mismatch when they differ from those there.
  void register_service(const std::string& name, const std::string& record, bool write);
  // The stream of the source `name`, its type recorded (or checked) in the registry.
  detail::Stream open_stream(const std::string& name, const Qos& qos, const Fingerprint& type, bool write);
  // The same for a type as the registry records it.
  detail::Stream open_stream(const std::string& name, const Qos& qos, const std::string& record, bool write);
  // A name for a chain's own service, unique in the domain.
  std::string private_name();
  // A chain's route to the service `name`, shown as `shown` in messages.
  detail::Segment segment(const std::string& name, std::string shown) const;
  // Hosts `handler` as the service `name`: alive from now on, with its
  // workers (the core's own threads, not the runtime's: stopping stops them
  // first, so they answer what they are running while the workers that
  // called them still wait).
  void host(const std::string& name, const std::string& shown, detail::Handler handler, const ServeOptions& serve_options);

  // How long a stopping core lets chain calls under way finish before it cuts them.
  static constexpr std::chrono::milliseconds kStopGrace{500};

  Options options_;
  std::shared_ptr<detail::Pool> pool_;
  std::mutex services_mutex_;
  bool stopping_ = false;
  std::vector<std::jthread> services_;
  std::vector<std::string> alive_keys_;  // of every service hosted here
};

static_assert(Medium<Core>);

}  // namespace prime::optimus
