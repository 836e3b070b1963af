// `prime --redis URL` on Optimus domains: their sources (Redis streams) and
// services, as the registry hashes of the domain list them.
#include <algorithm>
#include <charconv>
#include <chrono>
#include <cstdint>
#include <cstdlib>
#include <deque>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <sstream>
#include <string>
#include <string_view>
#include <vector>

#include "dot.hpp"
#include "json.hpp"
#include "message_text.hpp"
#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/optimus/detail/connection.hpp"
#include "prime/optimus/detail/keys.hpp"
#include "prime/optimus/detail/stream_protocol.hpp"
#include "shm_commands.hpp"
#include "stats.hpp"
#include "table.hpp"
#include "watch.hpp"

namespace prime::tool {

namespace {

// One connection to the server, as Optimus opens its own (tcp:// or
// unix://, the same errors), for the tool's few commands.
class Redis {
 public:
  explicit Redis(const std::string& url) : connection_{open(url)} {}

  // The reply to `words`, or a Failure naming what went wrong.
  prime::optimus::detail::Reply command(const std::vector<std::string>& words) {
    const std::vector<std::string_view> args(words.begin(), words.end());
    auto reply = connection_.command(args);
    if (!reply) throw Failure{reply.error()};
    if ((*reply)->type == REDIS_REPLY_ERROR)
      throw Failure{{Errc::unreachable, "redis: " + std::string{(*reply)->str, (*reply)->len}}};
    return std::move(*reply);
  }

 private:
  // Credentials come in the URL (tcp://user:password@host:port), or, kept
  // off the command line (where `ps` shows them), from PRIME_REDIS_USER and
  // PRIME_REDIS_PASSWORD.
  static prime::optimus::detail::Connection open(const std::string& url) {
    const auto endpoint = prime::optimus::detail::parse_url(url);
    if (!endpoint) throw Failure{endpoint.error()};
    prime::optimus::Options options{.url = url};
    if (const char* password = std::getenv("PRIME_REDIS_PASSWORD"); password && *password) {
      options.password = password;
      if (const char* user = std::getenv("PRIME_REDIS_USER"); user && *user) options.username = user;
    }
    auto connection = prime::optimus::detail::Connection::open(options, *endpoint);
    if (!connection) throw Failure{connection.error()};
    return std::move(*connection);
  }

  prime::optimus::detail::Connection connection_;
};

std::map<std::string, std::string> hash(Redis& r, const std::string& key) {
  std::map<std::string, std::string> out;
  auto reply = r.command({"HGETALL", key});
  for (std::size_t i = 0; i + 1 < reply->elements; i += 2)
    out[std::string{reply->element[i]->str, reply->element[i]->len}] = std::string{reply->element[i + 1]->str, reply->element[i + 1]->len};
  return out;
}

long long integer(Redis& r, const std::vector<std::string>& words) {
  auto reply = r.command(words);
  return reply->type == REDIS_REPLY_INTEGER ? reply->integer : 0;
}

// A source's readers: the "r<id>" fields of its readers hash (a reader that
// has lost values also has an "l<id>" field there).
long long readers(Redis& r, const Options& o, const std::string& source) {
  auto reply = r.command({"HKEYS", prime::optimus::detail::readers_key(o.domain, source)});
  long long n = 0;
  for (std::size_t i = 0; i < reply->elements; ++i)
    if (reply->element[i]->len > 0 && reply->element[i]->str[0] == 'r') ++n;
  return n;
}

// "0123456789abcdef Pose (24 bytes, ...)" -> "Pose (24 bytes, ...)"
std::string described(const std::string& record) {
  const auto space = record.find(' ');
  return space == std::string::npos ? record : record.substr(space + 1);
}

struct Endpoints {
  std::map<std::string, std::string> sources, services;
};

Endpoints endpoints(Redis& r, const Options& o) {
  return {hash(r, prime::optimus::detail::sources_key(o.domain)), hash(r, prime::optimus::detail::services_key(o.domain))};
}

// The entries appended to a source's stream from now on, one at a time
// (read a hundred at a time).
class StreamTail {
 public:
  struct Entry {
    std::string id{};
    std::optional<Clock::time_point> stamp{};  // its sensor's; none in an entry not Prime's
    std::string data{};
  };

  StreamTail(Redis& r, std::string stream) : r_{r}, stream_{std::move(stream)} {}

  // The next entry, waiting for it up to `timeout`.
  std::optional<Entry> next(Clock::duration timeout) {
    if (buffered_.empty()) {
      // At least 1 ms: BLOCK 0 would wait for ever.
      const auto ms = std::max<long long>(1, std::chrono::duration_cast<std::chrono::milliseconds>(timeout).count());
      auto reply = r_.command({"XREAD", "COUNT", "100", "BLOCK", std::to_string(ms), "STREAMS", stream_, last_});
      if (reply->type == REDIS_REPLY_ARRAY && reply->elements > 0) {
        const auto* entries = reply->element[0]->element[1];
        for (std::size_t i = 0; i < entries->elements; ++i) buffered_.push_back(entry(*entries->element[i]));
        if (!buffered_.empty()) last_ = buffered_.back().id;
      }
    }
    if (buffered_.empty()) return std::nullopt;
    auto front = std::move(buffered_.front());
    buffered_.pop_front();
    return front;
  }

 private:
  static Entry entry(const redisReply& e) {
    Entry out{.id = std::string{e.element[0]->str, e.element[0]->len}};
    const auto& fields = *e.element[1];
    for (std::size_t f = 0; f + 1 < fields.elements; f += 2) {
      const std::string_view name{fields.element[f]->str, fields.element[f]->len};
      const std::string_view value{fields.element[f + 1]->str, fields.element[f + 1]->len};
      if (name == "d") out.data = std::string{value};
      std::int64_t ns = 0;
      if (name == "t" && std::from_chars(value.data(), value.data() + value.size(), ns).ec == std::errc{})
        out.stamp = Clock::time_point{std::chrono::nanoseconds{ns}};
    }
    return out;
  }

  Redis& r_;
  std::string stream_;
  std::string last_ = "$";
  std::deque<Entry> buffered_;
};

}  // namespace

int optimus_ls(const Options& o) {
  Redis r{o.redis};
  const auto e = endpoints(r, o);
  if (e.sources.empty() && e.services.empty())
    throw Failure{{Errc::not_found, "no Optimus domain '" + o.domain + "' on " +
                                        prime::optimus::detail::without_password(o.redis) + " (no source or service registered)"}};
  if (o.json) {
    std::string out = "{\"domain\":" + quote(o.domain) + ",\"sources\":[";
    bool first = true;
    for (const auto& [name, record] : e.sources) {
      out += std::string{first ? "" : ","} + "{\"name\":" + quote(name) + ",\"type\":" + quote(described(record)) +
             ",\"length\":" + std::to_string(integer(r, {"XLEN", prime::optimus::detail::stream_key(o.domain, name)})) + ",\"readers\":" +
             std::to_string(readers(r, o, name)) + "}";
      first = false;
    }
    out += "],\"services\":[";
    first = true;
    for (const auto& [name, record] : e.services) {
      out += std::string{first ? "" : ","} + "{\"name\":" + quote(name) + ",\"types\":" + quote(described(record)) +
             ",\"alive\":" + (integer(r, {"EXISTS", prime::optimus::detail::alive_key(prime::optimus::detail::service_key(o.domain, name))}) ? "true" : "false") + "}";
      first = false;
    }
    std::cout << out << "]}\n";
    return kOk;
  }
  std::cout << "optimus domain " << o.domain << " on " << prime::optimus::detail::without_password(o.redis) << "\n\nSOURCES\n";
  Table sources{{"NAME", "TYPE", "IN STREAM", "READERS"}};
  for (const auto& [name, record] : e.sources)
    sources.add({name, described(record), std::to_string(integer(r, {"XLEN", prime::optimus::detail::stream_key(o.domain, name)})),
                 std::to_string(readers(r, o, name))});
  sources.print(std::cout);
  std::cout << "\nSERVICES\n";
  Table services{{"NAME", "TYPES", "ALIVE"}};
  for (const auto& [name, record] : e.services)
    services.add({name, described(record), integer(r, {"EXISTS", prime::optimus::detail::alive_key(prime::optimus::detail::service_key(o.domain, name))}) ? "yes" : "no"});
  services.print(std::cout);
  return kOk;
}

int optimus_info(const Options& o) {
  Redis r{o.redis};
  const auto e = endpoints(r, o);
  if (auto s = e.sources.find(o.name); s != e.sources.end()) {
    std::cout << "source " << o.name << "\n  type: " << described(s->second) << "\n  stream: " << prime::optimus::detail::stream_key(o.domain, o.name)
              << "\n  in stream: " << integer(r, {"XLEN", prime::optimus::detail::stream_key(o.domain, o.name)})
              << "\n  readers: " << readers(r, o, o.name) << '\n';
    return kOk;
  }
  if (auto v = e.services.find(o.name); v != e.services.end()) {
    std::cout << "service " << o.name << "\n  types: " << described(v->second) << "\n  alive: "
              << (integer(r, {"EXISTS", prime::optimus::detail::alive_key(prime::optimus::detail::service_key(o.domain, o.name))}) ? "yes" : "no") << '\n';
    return kOk;
  }
  throw Failure{{Errc::not_found, "no source or service '" + o.name + "' in Optimus domain '" + o.domain + "'"}};
}

int optimus_watch(const Options& o, const std::string& command) {
  Redis r{o.redis};
  if (!endpoints(r, o).sources.contains(o.name))
    throw Failure{{Errc::not_found, "no source '" + o.name + "' in Optimus domain '" + o.domain + "'"}};
  StreamTail tail{r, prime::optimus::detail::stream_key(o.domain, o.name)};
  if (command != "echo")
    return watch(o, command, [&](Clock::duration timeout) -> std::optional<Arrival> {
      auto entry = tail.next(timeout);
      if (!entry) return std::nullopt;
      return Arrival{entry->data.size(), entry->stamp};
    });
  finish_on_ctrl_c();
  std::size_t seen = 0;
  const auto first_by = first_sample_by(o, Clock::now());
  while (!ctrl_c_pressed() && (o.count == 0 || seen < o.count)) {
    auto entry = tail.next(std::chrono::milliseconds{200});
    if (!entry) {
      if (seen == 0 && Clock::now() >= first_by) return nothing_published(o);
      continue;
    }
    ++seen;
    const std::span<const std::byte> bytes{reinterpret_cast<const std::byte*>(entry->data.data()), entry->data.size()};
    const auto id = prime::optimus::detail::entry_id(entry->id);
    const auto sequence = id ? std::to_string(id->seq) : "null";
    const auto stamp = entry->stamp ? std::to_string(entry->stamp->time_since_epoch().count()) : "null";
    if (o.json)
      std::cout << "{\"sequence\":" << sequence << ",\"stamp_ns\":" << stamp << ",\"size\":" << bytes.size()
                << ",\"bytes\":" << quote(hex(bytes, bytes.size())) << "}" << std::endl;
    else
      std::cout << "sequence: " << (id ? sequence : "?") << "\nstamp: " << (entry->stamp ? stamp + " ns" : "?")
                << "\nsize: " << bytes.size() << "\nbytes: " << hex(bytes) << "\n---" << std::endl;
  }
  return after_ctrl_c(o.count == 0, seen > 0 ? int{kOk} : int{kNothing});
}

int optimus_graph(const Options& o) {
  Redis r{o.redis};
  const auto e = endpoints(r, o);
  std::cout << "digraph prime {\n  rankdir=LR;\n  label=" << quote("optimus domain " + o.domain) << ";\n";
  for (const auto& [name, record] : e.sources)
    std::cout << "  " << quote("source:" + name) << " [shape=ellipse, label=" << dot_label({name, described(record)}) << "];\n";
  for (const auto& [name, record] : e.services)
    std::cout << "  " << quote("service:" + name) << " [shape=hexagon, label=" << dot_label({name, described(record)}) << "];\n";
  std::cout << "}\n";
  return kOk;
}

}  // namespace prime::tool
