// The untyped part of an Optimus core (core.hpp): its connection pool,
// registry, streams and the workers of the services it hosts.
#include "prime/optimus/core.hpp"

#include <algorithm>
#include <charconv>
#include <cstdio>
#include <string_view>

#include "prime/optimus/detail/keys.hpp"
#include "prime/optimus/detail/pool.hpp"
#include "prime/optimus/detail/registry.hpp"
#include "prime/optimus/detail/service.hpp"
#include "prime/optimus/detail/stream_writer.hpp"
#include "prime/topology/detail/quiet_threads.hpp"

namespace prime::optimus {

Core::Core(Options options) : Runtime{"optimus"}, options_{std::move(options)}, pool_{detail::Pool::make(options_)} {
  if (options_.domain.empty()) throw Failure{{Errc::invalid_argument, "optimus: the domain (key prefix) must not be empty"}};
  auto lease = pool_->acquire();
  if (!lease) throw Failure{lease.error()};
  auto pong = (*lease)->command({"PING"});
  if (!pong) throw Failure{pong.error()};
  if (detail::is_error(**pong)) throw Failure{detail::server_error(**pong, "redis at " + pool_->url())};
}

Core::~Core() { stop(); }

void Core::stop() {
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

const std::string& Core::url() const noexcept { return pool_->url(); }

std::string Core::type_record(const Fingerprint& type) { return detail::type_record(type); }

void Core::register_service(const std::string& name, const std::string& record, bool write) {
  detail::register_types(*pool_, detail::services_key(pool_->domain()), name, record, "service '" + name + "'", write);
}

detail::Stream Core::open_stream(const std::string& name, const Qos& qos, const Fingerprint& type, bool write) {
  return open_stream(name, qos, detail::type_record(type), write);
}

detail::Stream Core::open_stream(const std::string& name, const Qos& qos, const std::string& record, bool write) {
  auto state = std::make_shared<detail::StreamState>(pool_, name, qos, runtime());
  detail::register_types(*pool_, detail::sources_key(pool_->domain()), name, record, "source '" + name + "'", write);
  return detail::Stream{std::move(state)};
}

RawPublisher Core::raw_publisher(const std::string& name, const std::string& record, Qos qos) {
  // A record begins with the type's fingerprint hash, as type_record
  // writes it: 16 lowercase hex digits, then a space.
  const auto hex = std::string_view{record}.substr(0, 16);
  std::uint64_t hash = 0;
  const bool lower = std::ranges::all_of(hex, [](char c) { return (c >= '0' && c <= '9') || (c >= 'a' && c <= 'f'); });
  if (record.size() < 18 || record[16] != ' ' || !lower ||
      std::from_chars(hex.data(), hex.data() + hex.size(), hash, 16).ec != std::errc{})
    throw Failure{{Errc::invalid_argument, "source '" + name + "': not a type as the registry records one (a 16-digit hash, then its "
                                           "description)"}};
  return RawPublisher{open_stream(name, qos, record, true), hash};
}

std::string Core::private_name() { return "~" + pool_->process_id() + "/" + std::to_string(pool_->next_id()); }

detail::Segment Core::segment(const std::string& name, std::string shown) const {
  return detail::Segment{pool_, {detail::service_key(pool_->domain(), name)}, {std::move(shown)}};
}

// A service is alive from the moment it is hosted (a linked call hands on
// only to a live one): its key is set here, then kept by one thread of the
// core for all its services.
void Core::host(const std::string& name, const std::string& shown, detail::Handler handler,
                const ServeOptions& serve_options) {
  const auto key = detail::service_key(pool_->domain(), name);
  if (auto marked = detail::mark_alive(*pool_, {detail::alive_key(key)}); !marked)
    throw Failure{{marked.error().code, "service '" + shown + "': " + marked.error().message}};
  std::scoped_lock lock{services_mutex_};
  if (stopping_) throw Failure{{Errc::stopped, "service '" + shown + "': the optimus core is shutting down"}};
  alive_keys_.push_back(detail::alive_key(key));
  prime::detail::with_signals_blocked([&] {  // the program's signals are not these threads'
    if (alive_keys_.size() == 1)
      services_.emplace_back([this](std::stop_token stop) {
        detail::keep_alive(pool_, [this] {
          std::scoped_lock lock{services_mutex_};
          return alive_keys_;
        }, stop);
      });
    auto shared = std::make_shared<const detail::Handler>(std::move(handler));
    for (std::size_t i = 0; i < std::max<std::size_t>(serve_options.workers, 1); ++i) {
      services_.emplace_back([pool = pool_, shown, key, shared, weak = runtime()](std::stop_token stop) {
        prime::detail::RuntimeState::become_worker(stop);
        detail::serve_requests(pool, shown, key, *shared, weak, std::move(stop));
      });
    }
  });
}

}  // namespace prime::optimus
