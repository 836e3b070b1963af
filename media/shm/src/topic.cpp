// A topic's segment: made or opened by name, and the subscriber slots of
// participants that died reclaimed.
#include "prime/shm/detail/topic.hpp"

namespace prime::shm::detail {

namespace {

void set_up(std::byte* data, const Fingerprint& type, const TopicQos& qos, const TopicGeometry& geometry,
            const std::string& schema, std::uint64_t first) {
  auto* header = ::new (data) TopicHeader{};
  write_schema(header->schema, schema, type.size);
  header->overflow = static_cast<std::uint32_t>(qos.overflow);
  header->type = type;
  header->capacity = qos.capacity;
  header->chunk_count = geometry.chunk_count();
  header->max_message_size = qos.max_message_size;
  header->chunk_stride = geometry.chunk_stride();
  header->max_subscribers = qos.max_subscribers;
  header->max_held = qos.max_held;
  header->block_timeout_ns.store(saturating_cast<std::chrono::nanoseconds>(qos.block_timeout).count());
  header->ring_offset = geometry.ring_offset();
  header->info_offset = geometry.info_offset();
  header->chunks_offset = geometry.chunks_offset();
  header->head.store(first);
  // Each entry one lap behind the first sequence that will land in it: nothing published yet.
  auto* ring = reinterpret_cast<std::atomic<std::uint64_t>*>(data + header->ring_offset);
  const auto cap = qos.capacity;
  for (std::size_t k = 0; k < cap; ++k) {
    const auto lands = first + (k + cap - first % cap) % cap;
    ::new (ring + k) std::atomic<std::uint64_t>{RingEntry::pack(lands - cap, kNoChunk)};
    ::new (data + header->info_offset + k * sizeof(SampleInfo)) SampleInfo{};
  }
  for (std::size_t i = 0; i < header->chunk_count; ++i)
    ::new (data + header->chunks_offset + i * header->chunk_stride) ChunkHeader{};
  header->magic.store(kTopicMagic, std::memory_order_release);
}

}  // namespace

std::shared_ptr<Topic> Topic::open(std::shared_ptr<Registry> registry, const std::string& name, const Fingerprint& type,
                                   const TopicQos& qos, const std::string& schema, std::uint64_t first_sequence) {
  const TopicGeometry geometry{qos.capacity, qos.max_message_size, qos.max_subscribers, qos.max_held};
  registry->add(EndpointKind::topic, name);
  auto mapped = Mapped::open(*registry, name, geometry.bytes(),
                             [&](std::byte* data) { set_up(data, type, qos, geometry, schema, first_sequence); });
  auto topic = std::shared_ptr<Topic>{new Topic{std::move(registry), name, std::move(mapped)}};
  if (!(topic->header().type == type))
    throw Failure{{Errc::type_mismatch, Mapped::what(name) + " carries " + topic->header().type.describe() + ", not " +
                                            type.describe()}};
  return topic;
}

std::shared_ptr<Topic> Topic::inspect(std::shared_ptr<Registry> registry, const std::string& name) {
  auto mapped = Mapped::open_existing(*registry, name);
  if (!mapped) return nullptr;
  return std::shared_ptr<Topic>{new Topic{std::move(registry), name, std::move(*mapped)}};
}

TopicQos Topic::qos() const noexcept {
  const auto& h = *header_;
  return {.capacity = geometry().capacity,
          .max_message_size = geometry().max_message_size,
          .overflow = overflow_,
          .block_timeout = std::chrono::duration_cast<std::chrono::milliseconds>(
              std::chrono::nanoseconds{h.block_timeout_ns.load(std::memory_order_relaxed)}),
          .publish_fence = h.light_publisher.load(std::memory_order_relaxed) != 0 ? PublishFence::light : PublishFence::full,
          .max_subscribers = geometry().max_subscribers,
          .max_held = geometry().max_held};
}

bool Topic::reclaim_subscriber(std::size_t i) const {
  auto& slot = header_->subscribers[i];
  if (!registry_->take_to_clear(slot.owner)) return false;
  release_subscriber_holds(i);
  slot.cursor.store(kNoCursor);
  slot.lagging.store(0);
  slot.kept_end.store(0);
  header_->data.forget(1ull << i);  // it may have died asleep
  header_->full_fences_wanted.fetch_and(~(1ull << i));
  slot.owner.store(0);
  wake_publisher();
  return true;
}

void Topic::release_subscriber_holds(std::size_t i) const {
  const auto bit = 1ull << i;
  for (std::uint32_t c = 0; c < places_.chunk_count; ++c) chunk(c).holders.fetch_and(~bit);
}

std::size_t Topic::reclaim_dead_subscribers() const {
  std::size_t n = 0;
  for (std::size_t i = 0; i < kSlots; ++i) n += reclaim_subscriber(i) ? 1 : 0;
  return n;
}

Topic::Topic(std::shared_ptr<Registry> registry, std::string name, Mapped mapped)
    : registry_{std::move(registry)},
      name_{std::move(name)},
      mapped_{std::move(mapped)},
      header_{&mapped_.header()},
      // Read once more after the check: whatever it reads now, one of the two.
      overflow_{header_->overflow == static_cast<std::uint32_t>(Overflow::block) ? Overflow::block : Overflow::drop_oldest},
      places_{.rings = reinterpret_cast<std::atomic<std::uint64_t>*>(mapped_.data() + geometry().ring_offset()),
              .infos = std::launder(reinterpret_cast<SampleInfo*>(mapped_.data() + geometry().info_offset())),
              .chunks = mapped_.data() + geometry().chunks_offset(),
              .capacity = geometry().capacity,
              .mask = std::has_single_bit(geometry().capacity) ? geometry().capacity - 1 : 0,
              .stride = geometry().chunk_stride(),
              .chunk_count = geometry().chunk_count(),
              .max_size = geometry().max_message_size} {}

}  // namespace prime::shm::detail
