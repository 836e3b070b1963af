// A participant's cold paths: joining the domain, opening topics, hosting
// and binding services, the tools' raw handles, loop records. The typed
// templates of core.hpp reach them through non-template calls.
#include "prime/shm/core.hpp"

#include <fstream>

#include "prime/shm/detail/caller.hpp"
#include "prime/shm/detail/layout.hpp"
#include "prime/shm/detail/registry.hpp"
#include "prime/shm/detail/server.hpp"
#include "prime/shm/detail/snapshot.hpp"
#include "prime/shm/detail/topic.hpp"

namespace prime::shm {

namespace detail {

namespace {

// `qos` with its defaults filled in for messages of type `type`, or a
// Failure naming the topic and what is wrong.
TopicQos complete(const std::string& name, const Fingerprint& type, bool raw, TopicQos qos) {
  auto refuse = [&](const std::string& why) { throw Failure{{Errc::invalid_argument, "topic '" + name + "': " + why}}; };
  if (raw && qos.max_message_size == 0) refuse("a raw byte topic needs max_message_size");
  if (qos.max_message_size == 0) qos.max_message_size = type.size;
  if (qos.max_message_size < type.size)
    refuse("max_message_size " + std::to_string(qos.max_message_size) + " is smaller than " + type.describe());
  const TopicGeometry geometry{qos.capacity, qos.max_message_size, qos.max_subscribers, qos.max_held};
  if (const auto what = geometry.out_of_bounds(); !what.empty()) refuse("QoS out of bounds: " + what);
  return qos;
}

// `qos` with its defaults filled in for a service of `request` and `reply`,
// or a Failure naming the service and what is wrong.
ServiceQos complete(const std::string& name, const Fingerprint& request, bool raw_request, const Fingerprint& reply,
                    bool raw_reply, ServiceQos qos) {
  auto refuse = [&](const std::string& why) { throw Failure{{Errc::invalid_argument, "service '" + name + "': " + why}}; };
  if (raw_request && qos.max_request_size == 0) refuse("raw byte requests need max_request_size");
  if (raw_reply && qos.max_reply_size == 0) refuse("raw byte replies need max_reply_size");
  if (qos.max_request_size == 0) qos.max_request_size = request.size;
  if (qos.max_reply_size == 0) qos.max_reply_size = reply.size;
  if (qos.max_request_size < request.size) refuse("max_request_size is smaller than " + request.describe());
  if (qos.max_reply_size < reply.size) refuse("max_reply_size is smaller than " + reply.describe());
  if (qos.workers == 0 || qos.workers > kMaxWorkers)
    refuse("workers must be in [1, " + std::to_string(kMaxWorkers) + "], not " + std::to_string(qos.workers));
  const ServiceGeometry geometry{qos.max_request_size, qos.max_reply_size, qos.max_clients, qos.calls_per_client};
  if (const auto what = geometry.out_of_bounds(); !what.empty()) refuse("QoS out of bounds: " + what);
  if (qos.timeout <= std::chrono::milliseconds::zero()) refuse("the timeout must be positive");
  return qos;
}

bool same_layout(const TopicQos& a, const TopicQos& b) {
  return a.capacity == b.capacity && a.max_message_size == b.max_message_size && a.overflow == b.overflow &&
         a.max_subscribers == b.max_subscribers && a.max_held == b.max_held;
}

std::string describe(const TopicQos& q) {
  return "capacity " + std::to_string(q.capacity) + ", max_message_size " + std::to_string(q.max_message_size) +
         ", overflow " + (q.overflow == Overflow::block ? "block" : "drop_oldest") + ", max_subscribers " +
         std::to_string(q.max_subscribers) + ", max_held " + std::to_string(q.max_held);
}

// Topic `name` as it is, for the tools' handles; Errc::not_found when the
// domain has none.
std::shared_ptr<Topic> existing_topic(const std::shared_ptr<Registry>& registry, const std::string& name) {
  auto topic = Topic::inspect(registry, name);
  if (!topic) throw Failure{{Errc::not_found, "no topic '" + name + "' in shm domain '" + registry->domain() + "'"}};
  return topic;
}

std::string program_name() {
  std::ifstream comm{"/proc/self/comm"};
  std::string name;
  std::getline(comm, name);
  return name;
}

}  // namespace

std::size_t topic_memory(const Fingerprint& type, bool raw, const TopicQos& qos) {
  const auto q = complete("", type, raw, qos);
  return TopicGeometry{q.capacity, q.max_message_size, q.max_subscribers, q.max_held}.bytes();
}

}  // namespace detail

Core::Core(std::string domain, DomainOptions options)
    : ErasedChainRuntime{"shm"},
      registry_{detail::Registry::join(domain,
                                       {.permissions = options.permissions,
                                        .owner = options.owner.value_or(::geteuid()),
                                        .prefault = options.prefault},
                                       options.participant.empty() ? detail::program_name() : options.participant,
                                       options.only_if_alive)} {
  reclaim();
}

RegistrySnapshot Core::registry() { return detail::snapshot(registry_); }

std::size_t Core::reclaim() { return detail::reclaim(registry_); }

Reader<View<Bytes>> Core::observe(const std::string& name) {
  return Reader<View<Bytes>>{std::make_unique<SubscriptionReader<Bytes>>(
      detail::existing_topic(registry_, name), SubscribeQos{.spin = std::chrono::microseconds{0}}, runtime(), true)};
}

Subscription<Bytes> Core::raw_subscription(const std::string& name, SubscribeQos qos) {
  auto topic = detail::existing_topic(registry_, name);
  qos.history = std::min<std::size_t>(qos.history, topic->header().capacity);
  return Subscription<Bytes>{std::move(topic), qos, runtime(), Graph::node(name, "source", "shm")};
}

Subscription<Bytes> Core::raw_subscription(const std::string& name, const RawType& type, TopicQos topic_qos,
                                           SubscribeQos qos) {
  auto opened = open_topic(name, type.type, type.type == Fingerprint::of<Bytes>(), topic_qos, type.schema, "subscriber");
  qos.history = std::min<std::size_t>(qos.history, opened.capacity);
  return Subscription<Bytes>{std::move(opened.topic), qos, runtime(), Graph::node(name, "source", "shm")};
}

Publisher<Bytes> Core::raw_publisher(const std::string& name) {
  return Publisher<Bytes>{detail::existing_topic(registry_, name), std::chrono::milliseconds{1000}, PublishFence::full, {}};
}

Publisher<Bytes> Core::raw_publisher(const std::string& name, const Fingerprint& type, const std::string& schema,
                                     TopicQos qos) {
  const auto timeout = qos.block_timeout;
  // An existing topic is published on with its own QoS; a new one is made
  // with `qos` (a byte topic's has its max_message_size already).
  auto topic = detail::Topic::inspect(registry_, name);
  if (!topic) topic = open_topic(name, type, type == Fingerprint::of<Bytes>(), qos, schema, "publisher").topic;
  if (!(topic->header().type == type))
    throw Failure{{Errc::type_mismatch, "topic '" + name + "' carries " + topic->header().type.describe() + ", not " +
                                            type.describe()}};
  return Publisher<Bytes>{std::move(topic), timeout, PublishFence::full, {}};
}

ServiceChain<Bytes, Bytes> Core::raw_chain(const std::string& name, ClientQos qos) {
  auto service = detail::Service::open_existing(registry_, name);
  if (!service) throw Failure{{Errc::not_found, "no service '" + name + "' in shm domain '" + domain() + "'"}};
  const auto& h = service->header();
  return {bind(name, h.request_type, h.reply_type, qos), Graph::node(name, "service", "shm")};
}

void Core::raw_serve(const std::string& name, const RawType& request, const RawType& reply, detail::Handler handler,
                     ServiceQos qos) {
  const auto raw = Fingerprint::of<Bytes>();
  host_service(name, {request.type, request.type == raw, request.schema}, {reply.type, reply.type == raw, reply.schema}, qos,
               std::move(handler));
}

const std::string& Core::domain() const noexcept { return registry_->domain(); }

std::shared_ptr<prime::detail::LoopRecord> Core::record_loop(const std::string& name, Clock::duration period,
                                                             Clock::duration deadline) {
  struct Entry {
    Entry(std::shared_ptr<detail::Registry> r, std::size_t i) : registry{std::move(r)}, index{i} {}
    Entry(const Entry&) = delete;
    Entry& operator=(const Entry&) = delete;
    ~Entry() { registry->remove_loop(index); }
    const std::shared_ptr<detail::Registry> registry;
    const std::size_t index;
  };
  auto entry = std::make_shared<Entry>(registry_, registry_->add_loop(name, period, deadline));
  auto& record = registry_->loop_record(entry->index);
  return {std::move(entry), &record};
}

Core::Opened Core::open_topic(const std::string& name, const Fingerprint& type, bool raw, const TopicQos& asked,
                              const std::string& schema, const char* side) {
  const auto qos = detail::complete(name, type, raw, asked);
  std::scoped_lock lock{mutex_};
  auto topic = topics_[name].lock();
  if (topic && !(topic->header().type == type))
    throw Failure{{Errc::type_mismatch, "topic '" + name + "' carries " + topic->header().type.describe() + ", not " +
                                            type.describe()}};
  if (!topic) topics_[name] = topic = detail::Topic::open(registry_, name, type, qos, schema);
  if (const auto have = topic->qos(); !detail::same_layout(have, qos))
    throw Failure{{Errc::qos_mismatch, "topic '" + name + "' exists with " + detail::describe(have) + "; this " + side +
                                           " asks for " + detail::describe(qos)}};
  const auto capacity = static_cast<std::size_t>(topic->header().capacity);
  return {std::move(topic), capacity};
}

void Core::host_service(const std::string& name, const Way& request, const Way& reply, const ServiceQos& qos,
                        detail::Handler handler) {
  const detail::ServiceSpec spec{request.type, reply.type,
                                 detail::complete(name, request.type, request.raw, reply.type, reply.raw, qos),
                                 request.schema, reply.schema};
  auto service = detail::Service::open_to_serve(registry_, name, spec);
  auto server = std::make_shared<detail::Server>(std::move(service), spec.qos, std::move(handler),
                                                 [runtime = runtime()](Error e) {
                                                   if (auto r = runtime.lock()) r->report(std::move(e));
                                                 });
  auto owner = runtime().lock();
  for (std::size_t w = 0; w < spec.qos.workers; ++w) owner->spawn([server, w](std::stop_token stop) { server->work(w, stop); });
}

detail::Route Core::bind(const std::string& name, const Fingerprint& request, const Fingerprint& reply,
                         const ClientQos& qos) {
  return {std::make_shared<detail::Binding>(registry_, name, request, reply, qos)};
}

}  // namespace prime::shm
