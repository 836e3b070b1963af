#pragma once

#include <chrono>
#include <cstddef>
#include <string>

#include "prime/topology/qos.hpp"

namespace prime::shm {

// How a topic is laid out and behaves, chosen at run time. It belongs to the
// topic: whoever opens it first (publisher or subscriber) creates it with
// these values, and a publisher that asks for others later is refused with
// both named. Keep one constant per topic and use it at both ends.
struct TopicQos {
  std::size_t capacity = 64;  // samples a subscriber may fall behind (and history it may ask for)
  // Largest message in bytes; 0 means sizeof(T). Raw byte topics must set it.
  std::size_t max_message_size = 0;
  Overflow overflow = Overflow::drop_oldest;
  // How long a `block` publisher's loan waits for the slowest live subscriber
  // before it fails with Errc::timeout (naming the topic and that subscriber).
  std::chrono::milliseconds block_timeout{1000};
  std::size_t max_subscribers = 8;  // live subscriptions at once (at most 62)
  // Samples each subscriber may hold at once (views alive); the publisher
  // always has a free slot while subscribers keep to this. 0 means the
  // capacity, so that read_all() is always safe; set it lower for topics of
  // large messages, whose slots all take memory.
  std::size_t max_held = 0;
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

// How a process joins a domain.
struct DomainOptions {
  // Who may open the domain's segments: the creating user only by default.
  unsigned permissions = 0600;
  // How this participant is listed in the registry; empty: the program's name.
  std::string participant{};
};

}  // namespace prime::shm
