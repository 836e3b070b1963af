#pragma once

#include <algorithm>
#include <cstddef>
#include <functional>
#include <map>
#include <span>
#include <memory>
#include <mutex>
#include <string>
#include <type_traits>
#include <utility>

#include "prime/common/fingerprint.hpp"
#include "prime/common/schema.hpp"
#include "prime/logic/error.hpp"
#include "prime/logic/event.hpp"
#include "prime/shm/message.hpp"
#include "prime/shm/publisher.hpp"
#include "prime/shm/qos.hpp"
#include "prime/shm/registry.hpp"
#include "prime/shm/service.hpp"
#include "prime/shm/subscription.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/erased_chain.hpp"

namespace prime::shm {

namespace detail {

class Registry;  // the domain's registry, mapped (compiled in libprime_shm)
class Topic;     // a topic's segment, mapped (compiled in libprime_shm)

// The bytes of /dev/shm a topic of `type` (`raw`: Bytes) with `qos` takes.
// Throws Failure (Errc::invalid_argument) when the QoS is out of bounds.
std::size_t topic_memory(const Fingerprint& type, bool raw, const TopicQos& qos);

}  // namespace detail

// The bytes of /dev/shm a topic of T with `qos` takes (all reserved when it
// is created).
template <Message T>
[[nodiscard]] std::size_t topic_memory(const TopicQos& qos) {
  return detail::topic_memory(Fingerprint::of<T>(), std::is_same_v<T, Bytes>, qos);
}

// One participant of a shared-memory domain: it publishes and subscribes to
// the domain's topics, which other processes of the same domain see, and it
// runs local chains (erased, like Liberty's) after its subscriptions.
//
// A participant is alive while it holds its lease in the domain's registry,
// a file lock the kernel drops when the process dies, so liveness holds
// across pid namespaces (containers sharing /dev/shm). Joining a domain
// whose earlier participants are all dead removes what they left; the
// participant leaves when the Core and every publisher, subscription and
// view it made are gone, and the last participant to leave removes the
// domain's segments.
//
// Thread-safe.
class Core : public ErasedChainRuntime {
 public:
  explicit Core(std::string domain, DomainOptions options = {});
  ~Core() { stop(); }
  using ErasedChainRuntime::chain;  // this process's own chains, beside the service handles below

  // The publisher of topic `name`, creating the topic with `qos` if needed.
  // Throws Failure when the topic carries another type
  // (Errc::type_mismatch), has other QoS (Errc::qos_mismatch), has a live
  // publisher already (Errc::in_use), or does not fit in /dev/shm
  // (Errc::no_space).
  template <Message T>
  [[nodiscard]] Publisher<T> publisher(const std::string& name, TopicQos qos = {}) {
    auto topic = open<T>(name, qos, "publisher").topic;
    return Publisher<T>{std::move(topic), qos.block_timeout, qos.publish_fence, [runtime = runtime()](Error e) {
                          if (auto r = runtime.lock()) r->report(std::move(e));
                        }};
  }

  // A source of topic `name`'s samples, read in place. The topic is created
  // with `topic_qos` if no one has opened it yet. Throws as publisher() does.
  template <Message T>
  [[nodiscard]] Subscription<T> subscribe(const std::string& name, SubscribeQos qos = {}, TopicQos topic_qos = {}) {
    auto opened = open<T>(name, topic_qos, "subscriber");
    qos.history = std::min<std::size_t>(qos.history, opened.capacity);
    return Subscription<T>{std::move(opened.topic), qos, runtime(), Graph::node(name, "source", "shm")};
  }

  // A source of what `event` raises from now on, carried by the domain's
  // topic `name`: each emit is published into it (a failed publish goes to
  // errors()), so other processes of the domain see it too. `qos` gives
  // the topic's capacity, overflow and block timeout, and the readers' spin.
  // The event may be destroyed before or after the source.
  template <class T>
  [[nodiscard]] Subscription<T> source(Event<T>& event, std::string name = "source", Qos qos = {}) {
    static_assert(Message<T>,
                  "prime::shm: a source is a topic of the domain, so it carries trivially copyable messages "
                  "(bounded_string and bounded_vector for variable content); keep other types in a liberty::Core");
    validate(qos, name);
    const TopicQos topic{.capacity = qos.capacity, .overflow = qos.overflow, .block_timeout = qos.block_timeout};
    struct Feed {
      explicit Feed(Publisher<T> p) : publisher{std::move(p)} {}
      std::mutex mutex;  // events may be raised on several threads; a publisher takes one at a time
      Publisher<T> publisher;
      Connection connection;
    };
    auto feed = std::make_shared<Feed>(publisher<T>(name, topic));
    feed->connection = event.connect([weak = std::weak_ptr<Feed>{feed}, runtime = runtime()](Sample<T>&& s) {
      auto feed = weak.lock();
      if (!feed) return;
      std::scoped_lock lock{feed->mutex};
      if (auto sent = feed->publisher.publish(s.value, s.stamp); !sent)
        if (auto r = runtime.lock()) r->report(std::move(sent.error()));
    });
    auto topic_handle = open<T>(name, topic, "source").topic;
    return Subscription<T>{std::move(topic_handle), {.spin = qos.spin}, runtime(), Graph::node(name, "source", "shm"),
                           std::move(feed)};
  }

  // Hosts `block` — any callable or chain, of any medium — as the service
  // `name` of the domain, run by qos.workers workers of this core, until it
  // stops. A block that takes `const In&` reads each request in place, where
  // the caller wrote it; its result is made in place in the caller's cell
  // (or, in a linked call, in the next service's). Requests and replies are
  // trivially copyable messages; a block taking std::span<const std::byte>
  // (or giving std::vector<std::byte>) serves raw bytes. What the block
  // throws comes back to its caller, and the service serves on. Throws
  // Errc::in_use when a live server serves the name; takes over one that
  // died. Returns a chain that calls it.
  template <class In = prime::detail::Deduce, int&... ExplicitArgumentBarrier, class F>
  auto serve(const std::string& name, F block, ServiceQos qos = {}) {
    using I = chain_input_t<In, F>;
    using Request = detail::wire_t<I>;
    using Argument = std::conditional_t<std::is_same_v<Request, Bytes>, std::span<const std::byte>, const Request&>;
    static_assert(std::is_invocable_v<const F&, Argument>, "prime::shm: a service block must be callable with its request");
    using Reply = detail::wire_t<std::invoke_result_t<const F&, Argument>>;
    static_assert(Message<Request> && Message<Reply>,
                  "prime::shm: a service carries trivially copyable messages (or raw bytes) both ways");
    return host<Request, Reply>(name, qos, [block = std::move(block)](const std::byte* request, std::size_t size,
                                                                      std::byte* out, std::size_t capacity) -> std::size_t {
      if constexpr (std::is_same_v<Reply, Bytes>) {
        const auto reply = std::invoke(block, detail::Wire<Request>::view(request, size));
        if (reply.size() > capacity) throw reply_too_large(reply.size(), capacity);
        if (!reply.empty()) std::memcpy(out, reply.data(), reply.size());
        return reply.size();
      } else {
        if (sizeof(Reply) > capacity) throw reply_too_large(sizeof(Reply), capacity);
        ::new (out) Reply(std::invoke(block, detail::Wire<Request>::view(request, size)));  // made where the caller reads it
        return sizeof(Reply);
      }
    });
  }

  // Hosts a block that writes its answer itself, in place: for large
  // replies that should never be copied. For messages,
  // `void(const In&, Out&)` (the reply is default-initialised where the
  // caller reads it); for raw bytes (In or Out = shm::Bytes),
  // `std::size_t(std::span<const std::byte> request, std::span<std::byte> reply)`,
  // returning the reply's size. Otherwise as serve().
  template <Message In, Message Out, class F>
  auto serve_in_place(const std::string& name, F block, ServiceQos qos = {}) {
    return host<In, Out>(name, qos, [block = std::move(block)](const std::byte* request, std::size_t size, std::byte* out,
                                                               std::size_t capacity) -> std::size_t {
      if constexpr (std::is_same_v<Out, Bytes>) {
        const std::size_t n = std::invoke(block, detail::Wire<In>::view(request, size), std::span<std::byte>{out, capacity});
        if (n > capacity) throw reply_too_large(n, capacity);
        return n;
      } else {
        if (sizeof(Out) > capacity) throw reply_too_large(sizeof(Out), capacity);
        auto* reply = ::new (out) Out;
        std::invoke(block, detail::Wire<In>::view(request, size), *reply);
        return sizeof(Out);
      }
    });
  }

  // A chain that calls the service `name`, served by this process or any
  // other of the domain (now, or later: it binds on its first call). Link
  // two of them with `|` and the first one's output goes straight to the
  // second. See ServiceChain for how a call fails.
  template <Message In, Message Out>
  [[nodiscard]] ServiceChain<In, Out> chain(const std::string& name, ClientQos qos = {}) {
    return {bind(name, Fingerprint::of<In>(), Fingerprint::of<Out>(), qos), Graph::node(name, "service", "shm")};
  }

  // The domain's participants, topics, services and loops as they are now.
  [[nodiscard]] RegistrySnapshot registry();

  // Reclaims what dead participants left behind: their registry entries,
  // their subscriber slots and the samples those held, their client slots
  // of services and the calls those had in flight. Publishers and idle
  // services also do this, and each participant does it on joining. Returns
  // the subscriber and client slots freed.
  std::size_t reclaim();

  // For tools: reads topic `name` whatever its type, in the one subscriber
  // slot each topic keeps for tools (so it takes no real subscriber's, and
  // no `block` publisher ever waits for it). Views of it are raw bytes;
  // hold them briefly. Throws Errc::not_found when there is no such topic.
  [[nodiscard]] Reader<View<Bytes>> observe(const std::string& name);

  // A message type known only at run time: its fingerprint (as a C++
  // type's, Fingerprint::named) and its description (schema_of<T>()).
  // Fingerprint::of<Bytes>() is raw bytes.
  struct RawType {
    Fingerprint type;
    std::string schema;
  };
  // For bindings that know a type only at run time (Python): a source of
  // topic `name` whatever its type, whose readers read each sample's bytes
  // in place. Real subscribers, unlike observe(): each takes one of the
  // topic's subscriber slots, and a `block` publisher waits for it; and a
  // source, so sync() takes it. Throws Errc::not_found when there is no
  // such topic, and as subscribe() does.
  [[nodiscard]] Subscription<Bytes> raw_subscription(const std::string& name, SubscribeQos qos = {});
  // The same, the topic made with `topic_qos` if no one has made it yet.
  // Throws Errc::type_mismatch when it carries another type, and as
  // subscribe() does.
  [[nodiscard]] Subscription<Bytes> raw_subscription(const std::string& name, const RawType& type, TopicQos topic_qos,
                                                     SubscribeQos qos = {});

  // For tools: publishes on topic `name` whatever its type, as raw bytes
  // (the type's size, laid out as its description says). The topic must
  // exist (its type is its own) and have no live publisher.
  [[nodiscard]] Publisher<Bytes> raw_publisher(const std::string& name);
  // For tools: the same on topic `name` of type `type` (as a snapshot's
  // fingerprint gives it), which is opened with `schema` and `qos` if no
  // one has opened it yet (as `prime play` does with what a recording says
  // of its topics). Throws Errc::type_mismatch when the topic carries
  // another type, and as publisher() does.
  [[nodiscard]] Publisher<Bytes> raw_publisher(const std::string& name, const Fingerprint& type, const std::string& schema,
                                               TopicQos qos);

  // For tools: a raw-byte handle on service `name`, whatever its types.
  [[nodiscard]] ServiceChain<Bytes, Bytes> raw_chain(const std::string& name, ClientQos qos = {});

  // For bindings that know types only at run time (Python): serves `name`,
  // taking `request` and giving `reply`, by `handler`, which reads the
  // request's bytes where the caller wrote them, writes its reply into
  // `out` (room for `capacity` bytes) and returns the reply's size. Callers
  // typed in C++ bind to it when the fingerprints match. Otherwise as serve().
  void raw_serve(const std::string& name, const RawType& request, const RawType& reply, detail::Handler handler,
                 ServiceQos qos = {});

  [[nodiscard]] const std::string& domain() const noexcept;

  // Where a periodic loop of this core (prime::every) records its
  // statistics: an entry of the domain's registry, so that `prime ls` and
  // `prime info` show them while it runs; freed with the loop. Throws
  // Errc::domain_full when the domain lists its maximum of loops.
  [[nodiscard]] std::shared_ptr<prime::detail::LoopRecord> record_loop(const std::string& name, Clock::duration period,
                                                                      Clock::duration deadline);

 private:
  // A raw reply larger than its room: this service's max_reply_size, or, in
  // a linked call, the next service's max_request_size (its output is
  // written straight into that service's request).
  static Failure reply_too_large(std::size_t size, std::size_t room) {
    return Failure{{Errc::too_large, "a reply of " + std::to_string(size) + " bytes exceeds the " +
                                              std::to_string(room) + " bytes it may take (this service's max_reply_size, "
                                              "or in a linked call the next service's max_request_size)"}};
  }
  // A topic's segment, opened for T, and its ring's capacity.
  struct Opened {
    std::shared_ptr<detail::Topic> topic;
    std::size_t capacity;
  };
  template <Message T>
  Opened open(const std::string& name, const TopicQos& asked, const char* side) {
    return open_topic(name, Fingerprint::of<T>(), std::is_same_v<T, Bytes>, asked, schema_of<T>(), side);
  }
  // Topic `name` of `type` (`raw`: Bytes), opened by this core, or created
  // with `asked` (completed); throws Failure when it carries another type
  // or has other QoS, naming `side` (who asked).
  Opened open_topic(const std::string& name, const Fingerprint& type, bool raw, const TopicQos& asked,
                    const std::string& schema, const char* side);

  // Serves `name` with `handler` on qos.workers workers of this core;
  // returns a chain that calls it.
  template <Message Request, Message Reply>
  ServiceChain<Request, Reply> host(const std::string& name, const ServiceQos& qos, detail::Handler handler) {
    host_service(name, {Fingerprint::of<Request>(), std::is_same_v<Request, Bytes>, schema_of<Request>()},
                 {Fingerprint::of<Reply>(), std::is_same_v<Reply, Bytes>, schema_of<Reply>()}, qos, std::move(handler));
    return chain<Request, Reply>(name);
  }
  // One way of a service: its type, whether raw bytes, its description.
  struct Way {
    Fingerprint type;
    bool raw;
    std::string schema;
  };
  void host_service(const std::string& name, const Way& request, const Way& reply, const ServiceQos& qos,
                    detail::Handler handler);
  // A client's route to service `name`, bound on its first call.
  detail::Route bind(const std::string& name, const Fingerprint& request, const Fingerprint& reply, const ClientQos& qos);

  std::shared_ptr<detail::Registry> registry_;
  std::mutex mutex_;
  std::map<std::string, std::weak_ptr<detail::Topic>> topics_;
};

static_assert(Medium<Core>);

}  // namespace prime::shm
