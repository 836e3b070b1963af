#pragma once

#include <chrono>
#include <cstddef>
#include <optional>
#include <string>

#include <sys/types.h>

#include "prime/topology/qos.hpp"

namespace prime::shm {

// How a publish makes sure a subscriber on its way to sleep sees it (the
// subscriber raises its sleeper bit, then looks at the head; the publisher
// stores the head, then looks for sleepers: one must see the other).
enum class PublishFence {
  // Every publish fences fully: it waits for its stores to reach the
  // subscribers' CPUs, about one cache-line transfer. That bounds a
  // busy subscriber's throughput one message at a time (batches share it).
  full,
  // A publish only keeps the compiler from reordering. A subscriber of the
  // topic about to sleep pays instead, with membarrier(2): an interrupt, of
  // a few microseconds, to every CPU then running a process that publishes
  // a `light` topic (not only this topic's publisher). Each subscriber runs
  // at most 1000 a second: one that sleeps more often asks this publisher
  // for full fences until it sleeps less; so does one the system refuses
  // membarrier (a container's seccomp filter may), for good. For a
  // high-rate topic read by busy subscribers, where robot control cores
  // running light publishers can take the interrupts. Measure it: where a
  // subscriber's own hold on each sample is the bound, it gains nothing.
  light,
};

// How a topic is laid out and behaves, chosen at run time. Whoever opens the
// topic first (publisher or subscriber) creates it with these values; anyone
// who opens it later with others is refused with both named
// (Errc::qos_mismatch), whichever side started first. Keep one constant per
// topic and use it at both ends.
//
// A topic takes about  (capacity + max_subscribers × max_held + 2) ×
// round_up(128 + max_message_size, 128)  bytes of /dev/shm (each chunk's
// header block and its payload), plus a 6.5 KiB header and 24 bytes per
// ring entry, each part from a page, all reserved when it is created;
// shm::topic_memory<T>(qos) computes it.
struct TopicQos {
  std::size_t capacity = 64;  // samples a subscriber may fall behind (and history it may ask for)
  // Largest message in bytes; 0 means sizeof(T). Raw byte topics must set it.
  std::size_t max_message_size = 0;
  Overflow overflow = Overflow::drop_oldest;
  // The publisher's (not compared between the two sides): how long a `block`
  // publisher waits for a subscriber that reads nothing (acknowledges
  // nothing: a reader acknowledges what it read every capacity / 8 samples,
  // 16 at most, and whenever it has read everything or waits). Past it, that
  // subscriber is reported once on core.errors() and no longer waited for
  // (it loses what is overwritten before it reads it, counted in its
  // lost()) until it has caught up.
  std::chrono::milliseconds block_timeout{1000};
  PublishFence publish_fence = PublishFence::full;  // the publisher's (not compared)
  std::size_t max_subscribers = 8;  // subscribers at once (at most 61; one more slot is kept for tools)
  // Samples each subscriber may hold at once (views alive). The topic's
  // memory is sized for it, and each reader keeps to it: past it, a reader
  // reads on only once it releases a view. A sync over the topic keeps
  // about three quarters of it waiting for a match (at least 4 to sync).
  std::size_t max_held = 8;
};

// One subscriber's own choices.
struct SubscribeQos {
  // On joining, also deliver up to this many samples already published (at
  // most the topic's capacity): a late joiner's history.
  std::size_t history = 0;
  // How long a reader that finds nothing keeps checking before it sleeps on
  // the futex. Zero sleeps at once; idle readers always sleep.
  std::chrono::microseconds spin{50};
};

// How a service is hosted (Core::serve) and what it allows its clients:
// limits crossed are errors returned to the caller that name the limit and
// the service, never a hang.
struct ServiceQos {
  std::size_t workers = 1;  // threads taking requests; more than one call the block concurrently (at most 62)
  // How long a client waits for an answer when it names no timeout of its own.
  std::chrono::milliseconds timeout{1000};
  // Largest request and reply in bytes; 0 means sizeof the type. Raw byte
  // services (shm::Bytes) must set them.
  std::size_t max_request_size = 0;
  std::size_t max_reply_size = 0;
  std::size_t max_clients = 16;      // client handles at once, over every process
  std::size_t calls_per_client = 4;  // calls one client may have in flight at once (its threads, its posts)
  // The least time between two requests of one client; 0: no limit.
  std::chrono::microseconds min_interval{0};
  // Requests that may wait for a worker at once; 0: as many as there are
  // calls in flight (max_clients × calls_per_client, at most 256).
  std::size_t queue_depth = 0;
  // How long an idle worker keeps checking before it sleeps (an idle service costs no CPU).
  std::chrono::microseconds spin{50};
};

// How a client calls a service (Core::chain<In, Out>(name, qos)).
struct ClientQos {
  std::chrono::milliseconds timeout{0};  // per call; 0: the service's
  // With no live server: fail at once (0), or wait this long for one.
  std::chrono::milliseconds wait_for_service{0};
  // How long a caller checks for its answer before it sleeps on it.
  std::chrono::microseconds spin{50};
};

// How a process joins a domain.
struct DomainOptions {
  // Who may open the domain's segments: the creating user only by default.
  // A segment found with a permission bit beyond these is refused.
  unsigned permissions = 0600;
  // Whose segments are accepted: this process's effective user by default.
  // A domain shared by several users (permissions 0660, say) names the one
  // who makes its segments. A segment of anyone else is refused, naming
  // the file and its owner: another user could otherwise make a domain's
  // files first and map what its participants then write. A participant
  // whose owner is another user makes no segment: it joins the registry,
  // topics and services that user made (a missing one is Errc::not_found).
  std::optional<uid_t> owner{};
  // How this participant is listed in the registry; empty: the program's name.
  std::string participant{};
  // Join only a domain some live participant is in (Errc::not_found
  // otherwise): for tools that look at or act on a running system, which
  // must not clear what a dead one left, as joining a dead domain does.
  bool only_if_alive = false;
  // Map every page of each segment in as it is opened (the registry,
  // topics, services), so that the hot path takes no page fault: not the
  // first publish into a chunk, nor the first read of it. Costs the time
  // to map them at open (a few microseconds per 100 KiB) and no memory
  // beyond what the segment holds anyway (it is reserved at creation). A
  // real-time option, with prime::lock_memory() and a loop's Realtime.
  bool prefault = false;
};

}  // namespace prime::shm
