#pragma once

#include <chrono>
#include <memory>
#include <mutex>
#include <thread>
#include <vector>
#include <string>
#include <type_traits>
#include <utility>

#include "prime/common/fingerprint.hpp"
#include "prime/logic/block.hpp"
#include "prime/logic/error.hpp"
#include "prime/logic/event.hpp"
#include "prime/optimus/chain.hpp"
#include "prime/optimus/codec.hpp"
#include "prime/optimus/detail/keys.hpp"
#include "prime/optimus/detail/pool.hpp"
#include "prime/optimus/detail/registry.hpp"
#include "prime/optimus/detail/service.hpp"
#include "prime/optimus/detail/stream_writer.hpp"
#include "prime/optimus/options.hpp"
#include "prime/optimus/source.hpp"
#include "prime/topology/chain_factory.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/link.hpp"
#include "prime/topology/runtime.hpp"

namespace prime::optimus {

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
  explicit Core(Options options) : Runtime{"optimus"}, options_{std::move(options)}, pool_{detail::Pool::make(options_)} {
    if (options_.domain.empty()) throw Failure{{Errc::invalid_argument, "optimus: the domain (key prefix) must not be empty"}};
    auto lease = pool_->acquire();
    if (!lease) throw Failure{lease.error()};
    auto pong = (*lease)->command({"PING"});
    if (!pong) throw Failure{pong.error()};
    if (detail::is_error(**pong)) throw Failure{detail::server_error(**pong, "redis at " + pool_->url())};
  }
  Core(const Core&) = delete;
  Core& operator=(const Core&) = delete;
  ~Core() { stop(); }  // workers use what the members hold: stop them first
  using ChainFactory<Core>::chain;

  // Stops and joins every worker of this core (its services, linked
  // sources). Chain calls waiting meanwhile end with Errc::stopped: a worker
  // may be waiting on a service that is stopping too. Idempotent.
  void stop() {
    std::vector<std::jthread> services;
    {
      std::scoped_lock lock{services_mutex_};
      stopping_ = true;
      services.swap(services_);
    }
    for (auto& s : services) s.request_stop();  // each finishes (and answers) what it runs
    pool_->close_calls(kStopGrace);
    services.clear();  // joins
    Runtime::stop();
    pool_->reopen_calls();
  }

  // A chain of one block, hosted as a service of this process (one worker)
  // and called through the server.
  template <class In = prime::detail::Deduce, class F>
  [[nodiscard]] auto chain(F block, Graph graph) {
    using I = chain_input_t<In, F>;
    static_assert(Block<F, I>, "prime::optimus: a block must be callable as Out(In) and return a value");
    using O = block_output_t<F, I>;
    std::string shown = display_name(graph);
    std::string name = "~" + pool_->process_id() + "/" + std::to_string(pool_->next_id());
    host<I>(name, shown, std::move(block), ServeOptions{});
    return Chain<I, O>{{detail::Segment{pool_, {detail::service_key(pool_->domain(), name)}, {std::move(shown)}}},
                       std::move(graph), options_.call_timeout};
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
    detail::register_types(*pool_, detail::services_key(pool_->domain()), name, record<I, O>(), "service '" + name + "'", true);
    host<I>(name, name, std::move(block), serve_options);
    return service<I, O>(name, {.timeout = options_.call_timeout});
  }

  // A chain that calls the service `name`, hosted by this process or any
  // other. Throws Errc::type_mismatch when the service is registered with
  // other types; a service not (yet) running is an error of each call.
  template <class In, class Out>
  [[nodiscard]] Chain<In, Out> service(std::string name, CallOptions call = {}) {
    detail::register_types(*pool_, detail::services_key(pool_->domain()), name, record<In, Out>(), "service '" + name + "'", false);
    Graph graph = Graph::node(name, "service", "optimus");
    return Chain<In, Out>{{detail::Segment{pool_, {detail::service_key(pool_->domain(), name)}, {name}}}, std::move(graph),
                          call.timeout};
  }

  // A source of what `event` raises from now on, carried by a stream: each
  // emit appends to it (one round trip) before it returns.
  template <class T>
  [[nodiscard]] Source<T> source(Event<T>& event, std::string name = "source", Qos qos = {}) {
    auto state = make_stream<T>(name, qos, true);
    state->feed_from(event.connect([weak = std::weak_ptr<detail::StreamState>{state}](Sample<T>&& s) {
      auto state = weak.lock();
      if (!state) return;
      if (auto done = state->publish(encode_message(s.value), s.stamp); !done) state->report(done.error());
    }));
    return Source<T>{std::move(state), Graph::node(std::move(name), "source", "optimus")};
  }

  // The writing end of the named source, for any process of the domain to read.
  template <class T>
  [[nodiscard]] Publisher<T> publisher(std::string name, Qos qos = {}) {
    auto state = make_stream<T>(name, qos, true);
    Source<T> source{state, Graph::node(std::move(name), "source", "optimus")};
    return Publisher<T>{std::move(source), std::move(state)};
  }

  // The named source, published by this process or any other. `qos` is this
  // side's: the capacity of its readers.
  template <class T>
  [[nodiscard]] Source<T> subscribe(std::string name, Qos qos = {}) {
    auto state = make_stream<T>(name, qos, false);
    return Source<T>{std::move(state), Graph::node(std::move(name), "source", "optimus")};
  }

  [[nodiscard]] const Options& options() const noexcept { return options_; }
  // The server's URL, with the password it may carry as "***".
  [[nodiscard]] const std::string& url() const noexcept { return pool_->url(); }

 private:
  template <class I, class O>
  static std::string record() {
    return detail::type_record(Fingerprint::of<I>()) + " -> " + detail::type_record(Fingerprint::of<O>());
  }

  static std::string display_name(const Graph& graph) {
    std::string names = prime::detail::exit_names(graph);
    return names.empty() ? std::string{"chain"} : names;
  }

  template <class T>
  std::shared_ptr<detail::StreamState> make_stream(const std::string& name, const Qos& qos, bool write) {
    auto state = std::make_shared<detail::StreamState>(pool_, name, qos, runtime());
    detail::register_types(*pool_, detail::sources_key(pool_->domain()), name, detail::type_record(Fingerprint::of<T>()),
                           "source '" + name + "'", write);
    return state;
  }

  // Service workers are the core's own threads, not the runtime's: stopping
  // stops them first, so they answer what they are running while the
  // workers that called them still wait (see stop()).
  // A service is alive from the moment it is hosted (a linked call hands
  // on only to a live one): its key is set here, then kept by one thread of
  // the core for all its services.
  template <class I, class F>
  void host(const std::string& name, std::string shown, F block, const ServeOptions& serve_options) {
    auto shared = std::make_shared<const F>(std::move(block));
    const auto key = detail::service_key(pool_->domain(), name);
    if (auto marked = detail::mark_alive(*pool_, {detail::alive_key(key)}); !marked)
      throw Failure{{marked.error().code, "service '" + shown + "': " + marked.error().message}};
    std::scoped_lock lock{services_mutex_};
    if (stopping_) throw Failure{{Errc::stopped, "service '" + shown + "': the optimus core is shutting down"}};
    alive_keys_.push_back(detail::alive_key(key));
    if (alive_keys_.size() == 1)
      services_.emplace_back([this](std::stop_token stop) {
        detail::keep_alive(pool_, [this] {
          std::scoped_lock lock{services_mutex_};
          return alive_keys_;
        }, stop);
      });
    for (std::size_t i = 0; i < std::max<std::size_t>(serve_options.workers, 1); ++i) {
      services_.emplace_back([pool = pool_, shown, key, shared, weak = runtime()](std::stop_token stop) {
        prime::detail::RuntimeState::become_worker(stop);
        detail::serve_requests<I>(pool, shown, key, *shared, weak, std::move(stop));
      });
    }
  }

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
