// A service's segment: made by its server, opened by its clients, and the
// clients that died reclaimed.
#include "prime/shm/detail/service.hpp"

#include <random>

namespace prime::shm::detail {

namespace {

bool same_limits(const ServiceGeometry& g, const ServiceQos& q) {
  return g.max_request_size == q.max_request_size && g.max_reply_size == q.max_reply_size &&
         g.max_clients == q.max_clients && g.calls_per_client == q.calls_per_client;
}

void set_up(std::byte* data, const ServiceSpec& spec, const ServiceGeometry& geometry) {
  auto* h = ::new (data) ServiceHeader{};
  std::random_device random;
  h->incarnation = (std::uint64_t{random()} << 32 | random()) ^
                   static_cast<std::uint64_t>(std::chrono::steady_clock::now().time_since_epoch().count());
  const auto& q = spec.qos;
  h->request_type = spec.request_type;
  h->reply_type = spec.reply_type;
  write_schema(h->request_schema, spec.request_schema, spec.request_type.size);
  write_schema(h->reply_schema, spec.reply_schema, spec.reply_type.size);
  h->max_request_size = q.max_request_size;
  h->max_reply_size = q.max_reply_size;
  h->max_clients = q.max_clients;
  h->calls_per_client = q.calls_per_client;
  h->cell_count = geometry.cell_count();
  h->cell_stride = geometry.cell_stride();
  h->request_offset = geometry.request_offset();
  h->reply_offset = geometry.reply_offset();
  h->tail_offset = geometry.tail_offset();
  h->cells_offset = geometry.cells_offset();
  for (std::size_t i = 0; i < geometry.cell_count(); ++i) {
    auto* cell = data + h->cells_offset + i * h->cell_stride;
    ::new (cell) CellHeader{};
    ::new (cell + h->tail_offset) CellTail{};
  }
  h->magic.store(kServiceMagic, std::memory_order_release);
}

}  // namespace

std::shared_ptr<Service> Service::open_to_serve(std::shared_ptr<Registry> registry, const std::string& name,
                                                const ServiceSpec& spec) {
  const auto index = registry->add(EndpointKind::service, name);
  const auto what = Mapped::what(name);
  const ServiceGeometry geometry{spec.qos.max_request_size, spec.qos.max_reply_size, spec.qos.max_clients,
                                 spec.qos.calls_per_client};
  while (true) {
    auto mapped = Mapped::open(*registry, name, geometry.bytes(), [&](std::byte* data) { set_up(data, spec, geometry); });
    auto service = std::shared_ptr<Service>{new Service{registry, name, index, std::move(mapped)}};
    auto& h = service->header();
    if (registry->alive(h.server.load()))
      throw Failure{{Errc::in_use, what + " is served already by " + registry->describe(h.server.load())}};
    if (h.request_type == spec.request_type && h.reply_type == spec.reply_type && same_limits(service->geometry(), spec.qos))
      return service;
    service->mapped_.segment().remove_name(what);  // an earlier server's, for other types or limits: start afresh
  }
}

std::shared_ptr<Service> Service::open_existing(std::shared_ptr<Registry> registry, const std::string& name) {
  auto mapped = Mapped::open_existing(*registry, name);  // its geometry checked before it takes a registry entry
  if (!mapped) return nullptr;
  const auto index = registry->add(EndpointKind::service, name);
  return std::shared_ptr<Service>{new Service{std::move(registry), name, index, std::move(*mapped)}};
}

ServiceQos Service::qos() const noexcept {
  const auto& h = *header_;
  return {.workers = h.workers.load(),
          .timeout = std::chrono::duration_cast<std::chrono::milliseconds>(std::chrono::nanoseconds{h.timeout_ns.load()}),
          .max_request_size = geometry().max_request_size,
          .max_reply_size = geometry().max_reply_size,
          .max_clients = geometry().max_clients,
          .calls_per_client = geometry().calls_per_client,
          .min_interval = std::chrono::duration_cast<std::chrono::microseconds>(std::chrono::nanoseconds{h.min_interval_ns.load()}),
          .queue_depth = h.queue_depth.load()};
}

std::size_t Service::reclaim_dead_clients() const {
  std::size_t n = 0;
  for (std::size_t c = 0; c < geometry().max_clients; ++c) {
    auto& slot = header_->clients[c];
    if (!registry_->take_to_clear(slot.owner)) continue;
    for (std::size_t k = 0; k < geometry().calls_per_client; ++k) release(c * geometry().calls_per_client + k);
    slot.last_request.store(0);
    slot.owner.store(0);
    ++n;
  }
  return n;
}

Service::Service(std::shared_ptr<Registry> registry, std::string name, std::size_t index, Mapped mapped)
    : registry_{std::move(registry)},
      name_{std::move(name)},
      index_{static_cast<std::uint32_t>(index)},
      mapped_{std::move(mapped)},
      header_{&mapped_.header()},
      cells_{mapped_.data() + geometry().cells_offset()},
      stride_{geometry().cell_stride()} {}

}  // namespace prime::shm::detail
