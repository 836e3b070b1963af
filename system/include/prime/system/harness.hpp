#pragma once

#include <chrono>
#include <expected>
#include <functional>
#include <map>
#include <memory>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/reader.hpp"
#include "prime/system/host.hpp"

namespace prime::system {

// Tests one component alone, in this process, with no medium: the harness
// plays every other end of its ports. Say which ends the test uses, then
// start() builds the component, linked to them:
//
//   prime::system::Harness h{planner(), {{"gain", 3.0}}};
//   auto scans = h.feed<Scan>("sensors/lidar");          // what it subscribes to
//   auto commands = h.probe<Command>("planner/command");   // what it publishes
//   h.serve<Command, Applied>("driver/command", [](const Command&) { return Applied{true}; });
//   auto reset = h.caller<Reset, Done>("planner/reset");    // a service it serves
//   h.feed_from("sensors/odom", replay.source<Odometry>("sensors/odom"));  // or any source: a recording
//   h.start();
//   scans.publish(scan);
//   auto got = commands.read_for(1s);
//
// A probe sees every value published after start(). Ports the test leaves
// alone are linked to nothing: outputs go nowhere, calls fail not_found.
class Harness {
 public:
  explicit Harness(Component component, std::map<std::string, ParamValue> params = {})
      : component_{std::move(component)}, params_{std::move(params)} {}

  // Values the test publishes into a port the component subscribes to.
  template <class T>
  class Feed {
   public:
    std::expected<void, Error> publish(T value, Clock::time_point stamp = Clock::now()) const {
      if (!*output_) throw Failure{{Errc::invalid_argument, "harness: feed used before start()"}};
      return (*output_)->publish(std::move(value), stamp);
    }

   private:
    friend class Harness;
    std::shared_ptr<std::optional<Output<T>>> output_ = std::make_shared<std::optional<Output<T>>>();
  };

  // What the component publishes on a port.
  template <class T>
  class Probe {
   public:
    template <class Rep, class Period>
    std::expected<Sample<T>, Error> read_for(std::chrono::duration<Rep, Period> timeout) const {
      return reader().read_for(timeout);
    }
    std::optional<Sample<T>> try_read() const { return reader().try_read(); }

   private:
    friend class Harness;
    Reader<T>& reader() const {
      if (!*reader_) throw Failure{{Errc::invalid_argument, "harness: probe used before start()"}};
      return **reader_;
    }
    std::shared_ptr<std::optional<Reader<T>>> reader_ = std::make_shared<std::optional<Reader<T>>>();
  };

  // A service the component calls, answered by the test.
  template <class In, class Out, class F>
  void serve(const std::string& port, F block) {
    tester_ = std::move(tester_).template serves<In, Out>(port);
    steps_.push_back([port, block = std::move(block)](Context& ctx) mutable { ctx.serve<In, Out>(port, std::move(block)); });
  }
  template <class T>
  Feed<T> feed(const std::string& port) {
    Feed<T> feed;
    tester_ = std::move(tester_).template publishes<T>(port);
    steps_.push_back([port, out = feed.output_](Context& ctx) { out->emplace(ctx.output<T>(port)); });
    return feed;
  }
  // Values of a port the component subscribes to taken from `source`, any
  // Source of T, in the component's own threads and with its QoS: a
  // recording, say (prime::record::Replay's sources, played once start()
  // returns; they block rather than drop, and so does what reads them).
  template <class S>
  void feed_from(const std::string& port, S source) {
    using T = typename S::value_type;
    detail::FedInput<T> fed{[source](const Qos&) { return source.subscribe(); }, source.qos()};
    steps_.push_back([port, fed = std::move(fed)](Context& ctx) {
      std::scoped_lock lock{ctx.links_.mutex};
      ctx.links_.fed.emplace(port, fed);
    });
  }
  template <class T>
  Probe<T> probe(const std::string& port, Qos qos = {.capacity = 1024}) {
    Probe<T> probe;
    tester_ = std::move(tester_).template subscribes<T>(port, qos);
    steps_.push_back([port, qos, reader = probe.reader_](Context& ctx) { reader->emplace(ctx.input<T>(port).subscribe(qos)); });
    return probe;
  }
  // Calls to a service the component serves.
  template <class In, class Out>
  class Caller {
   public:
    std::expected<Out, Error> call(const In& in) const {
      if (!*client_) throw Failure{{Errc::invalid_argument, "harness: caller used before start()"}};
      return (*client_)->call(in);
    }

   private:
    friend class Harness;
    std::shared_ptr<std::optional<Client<In, Out>>> client_ = std::make_shared<std::optional<Client<In, Out>>>();
  };
  template <class In, class Out>
  Caller<In, Out> caller(const std::string& port) {
    Caller<In, Out> caller;
    tester_ = std::move(tester_).template calls<In, Out>(port);
    steps_.push_back([port, client = caller.client_](Context& ctx) { client->emplace(ctx.client<In, Out>(port)); });
    return caller;
  }

  // Builds the component, linked to the test's ends. Throws what Host does.
  void start() {
    if (host_) throw Failure{{Errc::invalid_argument, "harness: started twice"}};
    registry_.add(std::move(tester_).build([steps = steps_](Context& ctx) {
      for (const auto& step : steps) step(ctx);
    }));
    registry_.add(component_);
    // The test's ends are built first: its probes see the component's first value.
    host_.emplace(Plan{.process = "harness",
                       .instances = {{"harness", "harness"}, {component_.type(), component_.type(), params_}}},
                  registry_);
  }

  // Stops the component's loops and chains.
  void stop() {
    if (host_) host_->stop();
  }

  [[nodiscard]] liberty::Core& local() { return host_->local(); }

 private:
  Component component_;
  std::map<std::string, ParamValue> params_;
  Component tester_{"harness"};
  std::vector<std::function<void(Context&)>> steps_;
  Registry registry_;  // the host's components: the test's ends and the component
  std::optional<Host> host_;
};

}  // namespace prime::system
