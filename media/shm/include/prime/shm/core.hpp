#pragma once

#include <fstream>
#include <map>
#include <memory>
#include <mutex>
#include <string>
#include <utility>

#include "prime/common/fingerprint.hpp"
#include "prime/logic/error.hpp"
#include "prime/shm/detail/topic.hpp"
#include "prime/shm/publisher.hpp"
#include "prime/shm/qos.hpp"
#include "prime/shm/registry.hpp"
#include "prime/shm/subscription.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/erased_chain.hpp"

namespace prime::shm {

// One participant of a shared-memory domain: it publishes and subscribes to
// the domain's topics, which other processes of the same domain see, and it
// runs local chains (erased, like Liberty's) after its subscriptions.
// Joining a domain whose earlier participants are all dead removes what they
// left; the last participant to leave removes the domain's segments.
//
// Thread-safe.
class Core : public ErasedChainRuntime {
 public:
  explicit Core(std::string domain, DomainOptions options = {})
      : ErasedChainRuntime{"shm"}, domain_{std::move(domain)}, options_{std::move(options)}, registry_{domain_, options_.permissions} {
    if (domain_.empty()) throw Failure{{Errc::limit_exceeded, "shm: a domain needs a name"}};
    registry_.join(options_.participant.empty() ? program_name() : options_.participant);
  }
  ~Core() {
    stop();
    registry_.leave();
  }

  // The publisher of topic `name`, creating the topic with `qos` if needed.
  // Throws Failure when the topic carries another type, was made with
  // another QoS, or has a live publisher already.
  template <Message T>
  [[nodiscard]] Publisher<T> publisher(const std::string& name, TopicQos qos = {}) {
    auto topic = open<T>(name, qos);
    const auto have = topic->qos();
    auto want = qos;
    if (want.max_message_size == 0) want.max_message_size = Fingerprint::of<T>().size;
    if (want.max_held == 0) want.max_held = want.capacity;
    if (have.capacity != want.capacity || have.max_message_size != want.max_message_size ||
        have.overflow != want.overflow || have.max_subscribers != want.max_subscribers || have.max_held != want.max_held)
      throw Failure{{Errc::limit_exceeded, "topic '" + name + "' exists with " + describe(have) +
                                               "; this publisher asks for " + describe(want)}};
    return Publisher<T>{std::move(topic), qos.block_timeout, [runtime = runtime()](Error e) {
                          if (auto r = runtime.lock()) r->report(std::move(e));
                        }};
  }

  // A source of topic `name`'s samples, read in place. The topic is created
  // with `topic_qos` if no one has opened it yet. Throws Failure when it
  // carries another type.
  template <Message T>
  [[nodiscard]] Subscription<T> subscribe(const std::string& name, SubscribeQos qos = {}, TopicQos topic_qos = {}) {
    auto topic = open<T>(name, topic_qos);
    if (qos.history > topic->header().capacity) qos.history = topic->header().capacity;
    return Subscription<T>{std::move(topic), qos, runtime(), Graph::node(name, "source", "shm")};
  }

  // The domain's participants and topics as they are now.
  [[nodiscard]] RegistrySnapshot registry() { return registry_.snapshot(); }

  // Reclaims what dead participants left behind (their subscriber slots and
  // the samples they held). Publishers also do this when they run short, and
  // each participant does it on joining. Returns the subscriber slots freed.
  std::size_t reclaim() { return registry_.reclaim(); }

  [[nodiscard]] const std::string& domain() const noexcept { return domain_; }

 private:
  template <Message T>
  std::shared_ptr<detail::Topic> open(const std::string& name, const TopicQos& qos) {
    if constexpr (std::is_same_v<T, Bytes>) {
      if (qos.max_message_size == 0)
        throw Failure{{Errc::limit_exceeded, "topic '" + name + "': a raw byte topic needs max_message_size"}};
    }
    const auto type = Fingerprint::of<T>();
    std::scoped_lock lock{mutex_};
    if (auto known = topics_[name].lock()) {
      if (!(known->header().type == type))
        throw Failure{{Errc::type_mismatch, "topic '" + name + "' carries " + known->header().type.describe() +
                                                ", not " + type.describe()}};
      return known;
    }
    registry_.add_topic(name);
    auto topic = detail::Topic::open(domain_, name, type, qos, options_.permissions);
    topics_[name] = topic;
    return topic;
  }

  static std::string describe(const TopicQos& q) {
    return "capacity " + std::to_string(q.capacity) + ", max_message_size " + std::to_string(q.max_message_size) +
           ", overflow " + (q.overflow == Overflow::block ? "block" : "drop_oldest") + ", max_subscribers " +
           std::to_string(q.max_subscribers) + ", max_held " + std::to_string(q.max_held);
  }

  static std::string program_name() {
    std::ifstream comm{"/proc/self/comm"};
    std::string name;
    std::getline(comm, name);
    return name;
  }

  std::string domain_;
  DomainOptions options_;
  detail::Registry registry_;
  std::mutex mutex_;
  std::map<std::string, std::weak_ptr<detail::Topic>> topics_;
};

static_assert(Medium<Core>);

}  // namespace prime::shm
