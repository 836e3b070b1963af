// `prime --redis URL` on Optimus domains: their sources (Redis streams) and
// services, as the registry of the domain lists them (prime/optimus/inspect.hpp).
#include <chrono>
#include <cstdlib>
#include <iostream>
#include <optional>
#include <string>
#include <vector>

#include "dot.hpp"
#include "json.hpp"
#include "message_text.hpp"
#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/optimus/inspect.hpp"
#include "shm_commands.hpp"
#include "stats.hpp"
#include "table.hpp"
#include "watch.hpp"

namespace prime::tool {

namespace {

using prime::optimus::Inspector;

}  // namespace

// The domain on the server of --redis. Credentials come in the URL
// (tcp://user:password@host:port), or, kept off the command line (where
// `ps` shows them), from PRIME_REDIS_USER and PRIME_REDIS_PASSWORD.
prime::optimus::Options optimus_options(const Options& o) {
  prime::optimus::Options options{.url = o.redis, .domain = o.domain};
  if (const char* password = std::getenv("PRIME_REDIS_PASSWORD"); password && *password) {
    options.password = password;
    if (const char* user = std::getenv("PRIME_REDIS_USER"); user && *user) options.username = user;
  }
  return options;
}

Inspector optimus_inspector(const Options& o) { return Inspector{optimus_options(o)}; }

namespace {

template <class Summary>
const Summary* named(const std::vector<Summary>& all, const std::string& name) {
  for (const auto& s : all)
    if (s.name == name) return &s;
  return nullptr;
}

}  // namespace

int optimus_ls(const Options& o) {
  auto r = optimus_inspector(o);
  const auto sources = r.sources();
  const auto services = r.services();
  if (sources.empty() && services.empty())
    throw Failure{{Errc::not_found, "no Optimus domain '" + o.domain + "' on " + r.server() +
                                        " (no source or service registered)"}};
  if (o.json) {
    std::string out = "{\"domain\":" + quote(o.domain) + ",\"sources\":[";
    bool first = true;
    for (const auto& s : sources) {
      out += std::string{first ? "" : ","} + "{\"name\":" + quote(s.name) + ",\"type\":" + quote(s.type) +
             ",\"length\":" + std::to_string(s.length) + ",\"readers\":" + std::to_string(s.readers) + "}";
      first = false;
    }
    out += "],\"services\":[";
    first = true;
    for (const auto& v : services) {
      out += std::string{first ? "" : ","} + "{\"name\":" + quote(v.name) + ",\"types\":" + quote(v.types) +
             ",\"alive\":" + (v.alive ? "true" : "false") + "}";
      first = false;
    }
    std::cout << out << "]}\n";
    return kOk;
  }
  std::cout << "optimus domain " << o.domain << " on " << r.server() << "\n\nSOURCES\n";
  Table source_table{{"NAME", "TYPE", "IN STREAM", "READERS"}};
  for (const auto& s : sources) source_table.add({s.name, s.type, std::to_string(s.length), std::to_string(s.readers)});
  source_table.print(std::cout);
  std::cout << "\nSERVICES\n";
  Table service_table{{"NAME", "TYPES", "ALIVE"}};
  for (const auto& v : services) service_table.add({v.name, v.types, v.alive ? "yes" : "no"});
  service_table.print(std::cout);
  return kOk;
}

int optimus_info(const Options& o) {
  auto r = optimus_inspector(o);
  const auto sources = r.sources();  // named() points into these: they outlive its use
  const auto services = r.services();
  if (const auto* s = named(sources, o.name)) {
    std::cout << "source " << s->name << "\n  type: " << s->type << "\n  stream: " << s->stream
              << "\n  in stream: " << s->length << "\n  readers: " << s->readers << '\n';
    return kOk;
  }
  if (const auto* v = named(services, o.name)) {
    std::cout << "service " << v->name << "\n  types: " << v->types << "\n  alive: " << (v->alive ? "yes" : "no") << '\n';
    return kOk;
  }
  throw Failure{{Errc::not_found, "no source or service '" + o.name + "' in Optimus domain '" + o.domain + "'"}};
}

int optimus_watch(const Options& o, const std::string& command) {
  auto r = optimus_inspector(o);
  if (!named(r.sources(), o.name))
    throw Failure{{Errc::not_found, "no source '" + o.name + "' in Optimus domain '" + o.domain + "'"}};
  auto tail = r.tail(o.name);
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
    const auto sequence = entry->sequence ? std::to_string(*entry->sequence) : "null";
    const auto stamp = entry->stamp ? std::to_string(entry->stamp->time_since_epoch().count()) : "null";
    if (o.json)
      std::cout << "{\"sequence\":" << sequence << ",\"stamp_ns\":" << stamp << ",\"size\":" << bytes.size()
                << ",\"bytes\":" << quote(hex(bytes, bytes.size())) << "}" << std::endl;
    else
      std::cout << "sequence: " << (entry->sequence ? sequence : "?") << "\nstamp: " << (entry->stamp ? stamp + " ns" : "?")
                << "\nsize: " << bytes.size() << "\nbytes: " << hex(bytes) << "\n---" << std::endl;
  }
  return after_ctrl_c(o.count == 0, seen > 0 ? int{kOk} : int{kNothing});
}

int optimus_graph(const Options& o) {
  auto r = optimus_inspector(o);
  std::cout << "digraph prime {\n  rankdir=LR;\n  label=" << quote("optimus domain " + o.domain) << ";\n";
  for (const auto& s : r.sources())
    std::cout << "  " << quote("source:" + s.name) << " [shape=ellipse, label=" << dot_label({s.name, s.type}) << "];\n";
  for (const auto& v : r.services())
    std::cout << "  " << quote("service:" + v.name) << " [shape=hexagon, label=" << dot_label({v.name, v.types}) << "];\n";
  std::cout << "}\n";
  return kOk;
}

}  // namespace prime::tool
