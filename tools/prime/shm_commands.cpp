// `prime` on shared-memory domains.
#include "shm_commands.hpp"

#include <pthread.h>
#include <pwd.h>
#include <signal.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <charconv>
#include <atomic>
#include <chrono>
#include <cmath>
#include <csignal>
#include <cstring>
#include <iomanip>
#include <iostream>
#include <map>
#include <optional>
#include <set>
#include <sstream>
#include <thread>

#include "dot.hpp"
#include "json.hpp"
#include "message_text.hpp"
#include "prime/shm.hpp"
#include "stats.hpp"
#include "table.hpp"
#include "watch.hpp"

namespace prime::tool {

namespace {
std::atomic<bool> stop_requested{false};
}  // namespace

// Ctrl-C is taken by the command's own loop, synchronously: SIGINT is
// blocked on this (the main) thread and picked up by ctrl_c_pressed(). The
// handler stays for a thread of the process that does not block it (Prime's
// own threads, workers and recorders, block every signal). Taken this way,
// no signal is lost in a handler's delivery: under ThreadSanitizer, whose
// runtime defers and replays handlers, a SIGINT sent right after a SIGCONT
// sometimes never ran the handler at all.
void finish_on_ctrl_c() {
  std::signal(SIGINT, [](int) { stop_requested = true; });
  sigset_t interrupt;
  sigemptyset(&interrupt);
  sigaddset(&interrupt, SIGINT);
  pthread_sigmask(SIG_BLOCK, &interrupt, nullptr);
}
bool ctrl_c_pressed() {
  if (stop_requested) return true;
  // Looked for at most every millisecond: loops that ask per sample stay
  // as fast as they were.
  static Clock::time_point next_look{};
  const auto now = Clock::now();
  if (now < next_look) return false;
  next_look = now + std::chrono::milliseconds{1};
  sigset_t interrupt;
  sigemptyset(&interrupt);
  sigaddset(&interrupt, SIGINT);
  const timespec none{};  // a look, not a wait
  if (::sigtimedwait(&interrupt, nullptr, &none) == SIGINT) stop_requested = true;
  return stop_requested;
}
int after_ctrl_c(bool open_ended, int code) { return ctrl_c_pressed() && !open_ended ? int{kInterrupted} : code; }

Clock::time_point first_sample_by(const Options& o, Clock::time_point start) {
  if (o.timeout <= 0) return Clock::time_point::max();
  return start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.timeout));
}
int nothing_published(const Options& o) {
  std::cerr << "prime: nothing published on '" << o.name << "' within " << o.timeout << " s\n";
  return kNothing;
}

namespace {

using namespace std::chrono_literals;

// "prime::test::Pose (32 bytes, align 8, layout 1)" -> "prime::test::Pose"
std::string short_type(const std::string& described) { return described.substr(0, described.find(" (")); }

// "1,2,3": the pids of a list.
std::string joined(const std::vector<std::uint32_t>& list) {
  std::string out;
  for (auto p : list) out += (out.empty() ? "" : ",") + std::to_string(p);
  return out;
}
std::string pids(const std::vector<std::uint32_t>& list) { return list.empty() ? "-" : joined(list); }
std::string json_pids(const std::vector<std::uint32_t>& list) { return "[" + joined(list) + "]"; }

// "alice (uid 1000)", or "uid 1000" for a uid no user has.
std::string user_named(uid_t uid) {
  passwd entry{};
  passwd* user = nullptr;
  char text[1024];
  if (::getpwuid_r(uid, &entry, text, sizeof text, &user) == 0 && user)
    return std::string{user->pw_name} + " (uid " + std::to_string(uid) + ")";
  return "uid " + std::to_string(uid);
}

// The user whose domains this tool reads and joins: --owner (a user's name
// or uid), or this one. Another user's domain is never taken on trust:
// whoever made its files first chose what this tool would read and write.
uid_t trusted_owner(const Options& o) {
  if (o.owner.empty()) return ::geteuid();
  passwd entry{};
  passwd* user = nullptr;
  char text[1024];
  if (::getpwnam_r(o.owner.c_str(), &entry, text, sizeof text, &user) == 0 && user) return user->pw_uid;
  uid_t uid = 0;
  const auto [end, ec] = std::from_chars(o.owner.data(), o.owner.data() + o.owner.size(), uid);
  if (ec != std::errc{} || end != o.owner.data() + o.owner.size())
    throw Failure{{Errc::not_found, "--owner " + quote(o.owner) + ": no such user on this machine"}};
  return uid;
}

// The domain as it was set up: who made it and whom its files admit. A
// domain that is not there, or was made by a user not trusted, is an error.
shm::DomainAccess access_to(const Options& o) {
  const auto access = shm::access_of(o.domain);
  if (!access) throw Failure{{Errc::not_found, "no shm domain '" + o.domain + "' on this machine (prime domains lists them)"}};
  if (const auto trusted = trusted_owner(o); access->owner != trusted)
    throw Failure{{Errc::unreachable, "shm domain '" + o.domain + "' was set up by " + user_named(access->owner) +
                                          ", not by " + user_named(trusted) +
                                          ": prime reads and joins it only when told to trust that user (--owner)"}};
  return *access;
}

}  // namespace

shm::RegistrySnapshot snapshot_of(const Options& o) {
  const auto access = access_to(o);
  auto seen = shm::inspect(o.domain, access.owner);
  if (!seen) throw Failure{{Errc::not_found, "no shm domain '" + o.domain + "' on this machine (prime domains lists them)"}};
  return *seen;
}

// How a command joins the domain (a participant named `participant`): as
// its participants do, with its owner's segments and its mode (a group's
// 0660 domain is joined as one of the group), and only while someone lives
// in it. Where the mode has bits no segment may have (execute, set-id),
// the participants' own checks refuse it.
shm::DomainOptions joining(const Options& o, const std::string& participant) {
  const auto access = access_to(o);
  return {.permissions = access.permissions & 0666u, .owner = access.owner, .participant = participant, .only_if_alive = true};
}

namespace {

// The topic or service of that name in a snapshot's list, or null.
template <class Endpoint>
const Endpoint* find_named(const std::vector<Endpoint>& list, const std::string& name) {
  const auto found = std::ranges::find(list, name, &Endpoint::name);
  return found == list.end() ? nullptr : &*found;
}
const shm::RegistrySnapshot::Topic* find_topic(const shm::RegistrySnapshot& s, const std::string& name) {
  return find_named(s.topics, name);
}
const shm::RegistrySnapshot::Service* find_service(const shm::RegistrySnapshot& s, const std::string& name) {
  return find_named(s.services, name);
}

std::string overflow_name(Overflow o) { return o == Overflow::block ? "block" : "drop_oldest"; }
std::string fence_name(shm::PublishFence f) { return f == shm::PublishFence::light ? "light" : "full"; }

// `rate`: as measured (ls), or none where nothing measured it (info).
std::string topic_json(const shm::RegistrySnapshot::Topic& t, std::optional<double> rate) {
  return "{\"name\":" + quote(t.name) + ",\"type\":" + quote(t.type) + ",\"capacity\":" + std::to_string(t.qos.capacity) +
         ",\"max_message_size\":" + std::to_string(t.qos.max_message_size) + ",\"overflow\":" +
         quote(overflow_name(t.qos.overflow)) + ",\"publish_fence\":" + quote(fence_name(t.qos.publish_fence)) +
         ",\"max_subscribers\":" + std::to_string(t.qos.max_subscribers) +
         ",\"max_held\":" + std::to_string(t.qos.max_held) + ",\"publisher_pid\":" + std::to_string(t.publisher_pid) +
         ",\"publisher\":" + quote(t.publisher) + ",\"subscriber_pids\":" + json_pids(t.subscriber_pids) +
         ",\"published\":" + std::to_string(t.published) + (rate ? ",\"rate\":" + fixed(*rate) : std::string{}) +
         ",\"schema\":" + quote(t.schema) + "}";
}

std::string service_json(const shm::RegistrySnapshot::Service& v) {
  return "{\"name\":" + quote(v.name) + ",\"request_type\":" + quote(v.request_type) + ",\"reply_type\":" +
         quote(v.reply_type) + ",\"server_pid\":" + std::to_string(v.server_pid) + ",\"server\":" + quote(v.server) +
         ",\"client_pids\":" + json_pids(v.client_pids) + ",\"served\":" + std::to_string(v.served) +
         ",\"failed\":" + std::to_string(v.failed) + ",\"workers\":" + std::to_string(v.qos.workers) +
         ",\"timeout_ms\":" + std::to_string(v.qos.timeout.count()) + ",\"max_clients\":" +
         std::to_string(v.qos.max_clients) + ",\"request_schema\":" + quote(v.request_schema) +
         ",\"reply_schema\":" + quote(v.reply_schema) + "}";
}

// A duration in milliseconds, to the microsecond.
std::string ms(Clock::duration d) { return fixed(std::chrono::duration<double, std::milli>{d}.count()); }
std::string ms_json(Clock::duration d) { return fixed(std::chrono::duration<double, std::milli>{d}.count(), 6); }

std::string loop_json(const shm::RegistrySnapshot::Loop& l) {
  const auto spread = [](const DurationStats& d) {
    return "{\"p50_ms\":" + ms_json(d.p50) + ",\"p99_ms\":" + ms_json(d.p99) + ",\"max_ms\":" + ms_json(d.max) + "}";
  };
  return "{\"name\":" + quote(l.name) + ",\"participant\":" + quote(l.participant) + ",\"pid\":" + std::to_string(l.pid) +
         ",\"period_ms\":" + ms_json(l.period) + ",\"deadline_ms\":" + ms_json(l.deadline) +
         ",\"ticks\":" + std::to_string(l.stats.ticks) + ",\"overruns\":" + std::to_string(l.stats.overruns) +
         ",\"skipped\":" + std::to_string(l.stats.skipped) + ",\"lateness\":" + spread(l.stats.lateness) +
         ",\"run_time\":" + spread(l.stats.run_time) + "}";
}

// A topic read by this tool in the slot each topic keeps for tools.
struct Watch {
  shm::Core core;
  Reader<shm::View<shm::Bytes>> reader;
  std::string schema;
  std::size_t max_message_size = 0;

  Watch(const Options& o, const std::string& command)
      : core{check(o), joining(o, "prime " + command)}, reader{core.observe(o.name)} {
    for (const auto& t : core.registry().topics)
      if (t.name == o.name) schema = t.schema, max_message_size = t.qos.max_message_size;
  }
  static std::string check(const Options& o) {
    snapshot_of(o);  // a domain that is not there is an error, not one this tool starts
    return o.domain;
  }
};

// The layout to show messages of up to `size` bytes by; none (they show as
// bytes) for a type with no description, or one that does not fit them,
// which is said once, naming the field.
std::shared_ptr<const Layout> layout_to_show(const std::string& schema, std::size_t size, const std::string& of) {
  try {
    auto layout = parse_layout(schema, size);
    if (layout->kind != Layout::Kind::opaque) return layout;
  } catch (const std::runtime_error& e) {
    std::cerr << "prime: the type description of " << of << " is refused, so its values show as bytes: " << e.what() << '\n';
  }
  return nullptr;
}

// A line of shm::clean's that says a segment stayed, with why; and, where
// the reason is that another user owns it (only a file's owner may remove
// it from /dev/shm), who that is. Nothing for any other line.
std::optional<std::string> failed_removal(const std::string& line) {
  const std::string failed = "could not remove ";
  if (!line.starts_with(failed)) return std::nullopt;
  const auto path = line.substr(failed.size(), line.find(": ") - failed.size());
  struct stat st {};
  if (::lstat(path.c_str(), &st) != 0 || st.st_uid == ::geteuid()) return line;
  return line + " (it belongs to " + user_named(st.st_uid) + ")";
}

}  // namespace

int shm_domains(const Options& o) {
  const auto found = shm::domains();
  if (o.json) {
    std::string out = "[";
    for (std::size_t i = 0; i < found.size(); ++i) {
      const auto& d = found[i];
      out += std::string{i ? "," : ""} + "{\"name\":" + quote(d.name);
      if (!d.unreadable.empty()) {
        out += ",\"unreadable\":" + quote(d.unreadable) + "}";
        continue;
      }
      out += ",\"participants_alive\":" + std::to_string(d.participants_alive) + ",\"participants_dead\":" +
             std::to_string(d.participants_dead) + ",\"topics\":" + std::to_string(d.topics) +
             ",\"services\":" + std::to_string(d.services) + "}";
    }
    std::cout << out << "]\n";
    return kOk;
  }
  Table table{{"DOMAIN", "ALIVE", "DEAD", "TOPICS", "SERVICES"}};
  std::vector<std::string> unreadable;
  for (const auto& d : found) {
    if (!d.unreadable.empty()) {
      table.add({d.name, "?", "?", "?", "?"});
      unreadable.push_back(d.name + ": " + d.unreadable);
      continue;
    }
    table.add({d.name, std::to_string(d.participants_alive), std::to_string(d.participants_dead), std::to_string(d.topics),
               std::to_string(d.services)});
  }
  if (table.empty()) std::cout << "no shared-memory domains on this machine\n";
  else table.print(std::cout);
  for (const auto& why : unreadable) std::cout << "could not read " << why << '\n';
  return kOk;
}

int shm_ls(const Options& o) {
  const auto first = snapshot_of(o);
  const auto t0 = Clock::now();
  std::this_thread::sleep_for(200ms);  // the rates: samples published over this time
  const auto second = snapshot_of(o);
  const auto seconds = std::chrono::duration<double>(Clock::now() - t0).count();
  auto rate = [&](const shm::RegistrySnapshot::Topic& t) {
    const auto* before = find_topic(first, t.name);
    // A topic made again meanwhile (its count began anew) shows no rate, not a wrapped one.
    return before && t.published >= before->published ? static_cast<double>(t.published - before->published) / seconds
                                                      : 0.0;
  };
  if (o.json) {
    std::string out = "{\"domain\":" + quote(o.domain) + ",\"participants\":[";
    for (std::size_t i = 0; i < second.participants.size(); ++i) {
      const auto& p = second.participants[i];
      out += std::string{i ? "," : ""} + "{\"name\":" + quote(p.name) + ",\"pid\":" + std::to_string(p.pid) +
             ",\"alive\":" + (p.alive ? "true" : "false") + "}";
    }
    out += "],\"topics\":[";
    for (std::size_t i = 0; i < second.topics.size(); ++i) out += (i ? "," : "") + topic_json(second.topics[i], rate(second.topics[i]));
    out += "],\"services\":[";
    for (std::size_t i = 0; i < second.services.size(); ++i) out += (i ? "," : "") + service_json(second.services[i]);
    out += "],\"loops\":[";
    for (std::size_t i = 0; i < second.loops.size(); ++i) out += (i ? "," : "") + loop_json(second.loops[i]);
    std::cout << out << "]}\n";
    return kOk;
  }
  std::cout << "domain " << o.domain << "\n\nPARTICIPANTS\n";
  Table participants{{"NAME", "PID", "ALIVE"}};
  for (const auto& p : second.participants) participants.add({p.name, std::to_string(p.pid), p.alive ? "yes" : "no"});
  participants.print(std::cout);
  std::cout << "\nTOPICS\n";
  Table topics{{"NAME", "TYPE", "QOS", "PUBLISHER", "SUBSCRIBERS", "PUBLISHED", "RATE"}};
  for (const auto& t : second.topics)
    topics.add({t.name, short_type(t.type), std::to_string(t.qos.capacity) + " " + overflow_name(t.qos.overflow),
                t.publisher_pid ? t.publisher + " (" + std::to_string(t.publisher_pid) + ")" : "-", pids(t.subscriber_pids),
                std::to_string(t.published), fixed(rate(t), 1) + " Hz"});
  topics.print(std::cout);
  std::cout << "\nSERVICES\n";
  Table services{{"NAME", "REQUEST", "REPLY", "SERVER", "CLIENTS", "CALLS", "FAILED"}};
  for (const auto& v : second.services)
    services.add({v.name, short_type(v.request_type), short_type(v.reply_type),
                  v.server_pid ? v.server + " (" + std::to_string(v.server_pid) + ")" : "-", pids(v.client_pids),
                  std::to_string(v.served), std::to_string(v.failed)});
  services.print(std::cout);
  std::cout << "\nLOOPS\n";
  Table loops{{"NAME", "PARTICIPANT", "PERIOD", "TICKS", "OVERRUNS", "LATE p99", "RUN p99", "RUN max"}};
  for (const auto& l : second.loops)
    loops.add({l.name, l.participant + " (" + std::to_string(l.pid) + ")", ms(l.period) + " ms", std::to_string(l.stats.ticks),
               std::to_string(l.stats.overruns), ms(l.stats.lateness.p99) + " ms", ms(l.stats.run_time.p99) + " ms",
               ms(l.stats.run_time.max) + " ms"});
  loops.print(std::cout);
  return kOk;
}

int shm_info(const Options& o) {
  const auto s = snapshot_of(o);
  auto fields = [](const std::string& schema) {
    std::ostringstream out;
    try {
      const auto layout = parse_layout(schema);
      if (layout->kind != Layout::Kind::record) return std::string{"  (no description: PRIME_DESCRIBE it to see fields)\n"};
      for (const auto& f : layout->fields) out << "  " << f.name << " @" << f.offset << "\n";
    } catch (const std::exception& e) {
      out << "  (" << e.what() << ")\n";
    }
    return out.str();
  };
  if (const auto* t = find_topic(s, o.name)) {
    if (o.json) {
      std::cout << topic_json(*t, std::nullopt) << '\n';
      return kOk;
    }
    std::cout << "topic " << t->name << "\n  type: " << t->type << "\n  capacity: " << t->qos.capacity
              << "\n  max_message_size: " << t->qos.max_message_size << "\n  overflow: " << overflow_name(t->qos.overflow)
              << "\n  block_timeout: " << t->qos.block_timeout.count()
              << " ms\n  publish_fence: " << fence_name(t->qos.publish_fence) << "\n  max_subscribers: " << t->qos.max_subscribers
              << "\n  max_held: " << t->qos.max_held << "\n  publisher: " << (t->publisher_pid ? t->publisher + " (pid " + std::to_string(t->publisher_pid) + ")" : "none")
              << "\n  subscribers: " << pids(t->subscriber_pids) << "\n  published: " << t->published << "\nfields\n"
              << fields(t->schema);
    return kOk;
  }
  if (const auto* v = find_service(s, o.name)) {
    if (o.json) {
      std::cout << service_json(*v) << '\n';
      return kOk;
    }
    std::cout << "service " << v->name << "\n  request: " << v->request_type << "\n  reply: " << v->reply_type
              << "\n  server: " << (v->server_pid ? v->server + " (pid " + std::to_string(v->server_pid) + ")" : "none")
              << "\n  workers: " << v->qos.workers << "\n  timeout: " << v->qos.timeout.count()
              << " ms\n  max_clients: " << v->qos.max_clients << "\n  calls_per_client: " << v->qos.calls_per_client
              << "\n  clients: " << pids(v->client_pids) << "\n  served: " << v->served << "\n  failed: " << v->failed
              << "\n  from callers: " << v->requests_from_callers << ", forwarded in: " << v->requests_forwarded_in
              << "\n  to callers: " << v->replies_to_callers << ", forwarded on: " << v->outputs_forwarded_on
              << "\nrequest fields\n" << fields(v->request_schema) << "reply fields\n" << fields(v->reply_schema);
    return kOk;
  }
  // Loops are named by their participant; several may share a name.
  std::vector<const shm::RegistrySnapshot::Loop*> loops;
  for (const auto& l : s.loops)
    if (l.name == o.name) loops.push_back(&l);
  if (!loops.empty()) {
    if (o.json) {
      std::string out = "[";
      for (std::size_t i = 0; i < loops.size(); ++i) out += (i ? "," : "") + loop_json(*loops[i]);
      std::cout << out << "]\n";
      return kOk;
    }
    for (const auto* l : loops) {
      const auto spread = [](const DurationStats& d) {
        return "p50 " + ms(d.p50) + " ms, p99 " + ms(d.p99) + " ms, max " + ms(d.max) + " ms";
      };
      std::cout << "loop " << l->name << "\n  participant: " << l->participant << " (pid " << l->pid << ")\n  period: "
                << ms(l->period) << " ms\n  deadline: " << ms(l->deadline) << " ms\n  ticks: " << l->stats.ticks
                << "\n  overruns: " << l->stats.overruns << "\n  skipped: " << l->stats.skipped
                << "\n  lateness: " << spread(l->stats.lateness) << "\n  run time: " << spread(l->stats.run_time) << '\n';
    }
    return kOk;
  }
  throw Failure{{Errc::not_found, "no topic, service or loop '" + o.name + "' in shm domain '" + o.domain + "'"}};
}

int shm_watch(const Options& o, const std::string& command) {
  Watch w{o, command};
  return watch(o, command, [&](Clock::duration timeout) -> std::optional<Arrival> {
    auto sample = w.reader.read_for(timeout);
    if (!sample) return std::nullopt;
    return Arrival{sample->value.bytes().size(), sample->stamp};
  });
}

int shm_echo(const Options& o) {
  Watch w{o, "echo"};
  const auto layout = layout_to_show(w.schema, w.max_message_size, "'" + o.name + "'");
  const auto reach = layout ? extent(*layout) : 0;
  finish_on_ctrl_c();
  std::size_t seen = 0;
  const auto first_by = first_sample_by(o, Clock::now());
  while (!ctrl_c_pressed() && (o.count == 0 || seen < o.count)) {
    auto sample = w.reader.read_for(100ms);
    if (!sample) {
      if (seen == 0 && Clock::now() >= first_by) return nothing_published(o);
      continue;
    }
    ++seen;
    const auto bytes = sample->value.bytes();
    const bool by_fields = layout && reach <= bytes.size();  // a sample shorter than its description: as bytes
    const auto stamp_ns = std::chrono::duration_cast<std::chrono::nanoseconds>(sample->stamp.time_since_epoch()).count();
    if (o.json) {
      std::cout << "{\"sequence\":" << sample->value.sequence() << ",\"stamp_ns\":" << stamp_ns << ",\"size\":" << bytes.size()
                << (by_fields ? ",\"value\":" + to_json(*layout, bytes.data()) : ",\"bytes\":" + quote(hex(bytes, bytes.size())))
                << "}" << std::endl;
    } else if (by_fields) {
      if (layout->kind == Layout::Kind::record) print_fields(std::cout, *layout, bytes.data());
      else std::cout << "value: " << to_json(*layout, bytes.data()) << '\n';
      std::cout << "---" << std::endl;
    } else {
      std::cout << "sequence: " << sample->value.sequence() << "\nstamp: " << stamp_ns << " ns\nsize: " << bytes.size()
                << "\nbytes: " << hex(bytes) << "\n---" << std::endl;
    }
  }
  return after_ctrl_c(o.count == 0, seen > 0 ? int{kOk} : int{kNothing});
}

namespace {

// The message `words` say (one JSON object, or field=value words), laid out
// as `schema` describes in `size` bytes, the rest zero.
std::vector<std::byte> build(const std::string& schema, std::size_t size, const std::vector<std::string>& words) {
  std::shared_ptr<const Layout> layout;
  try {
    layout = parse_layout(schema, size);
  } catch (const std::runtime_error& e) {
    throw Failure{{Errc::type_mismatch, std::string{"its type description does not fit its "} + std::to_string(size) +
                                            "-byte messages (damaged, or written by a foreign program): " + e.what()}};
  }
  if (layout->kind != Layout::Kind::record)
    throw Failure{{Errc::type_mismatch, "its type has no description (PRIME_DESCRIBE next to the type): it cannot be built from text"}};
  const auto value = words.size() == 1 && !words[0].empty() && words[0][0] == '{' ? parse_json(words[0]) : from_assignments(words);
  std::vector<std::byte> bytes(size);
  fill(*layout, bytes.data(), value);
  return bytes;
}

}  // namespace

int shm_pub(const Options& o) {
  const auto s = snapshot_of(o);
  const auto* t = find_topic(s, o.name);
  if (!t) throw Failure{{Errc::not_found, "no topic '" + o.name + "' in shm domain '" + o.domain + "' (its type comes from a publisher or subscriber)"}};
  const auto bytes = build(t->schema, t->qos.max_message_size, o.values);
  shm::Core core{o.domain, joining(o, "prime pub")};
  auto publisher = core.raw_publisher(o.name);
  finish_on_ctrl_c();
  const auto period = o.rate > 0 ? std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(1 / o.rate)) : Clock::duration::zero();
  std::size_t sent = 0;
  for (auto next = Clock::now(); !ctrl_c_pressed(); next += period) {
    while (!ctrl_c_pressed() && Clock::now() < next)  // in steps, so Ctrl-C ends a long period at once
      std::this_thread::sleep_until(std::min(next, Clock::now() + 100ms));
    if (ctrl_c_pressed()) break;
    if (auto done = publisher.publish(bytes); !done) throw Failure{done.error()};
    ++sent;
    if (o.rate == 0 || (o.count > 0 && sent >= o.count)) break;
  }
  if (!o.json) std::cout << "published " << sent << (sent == 1 ? " sample" : " samples") << " on '" << o.name << "'\n";
  return after_ctrl_c(o.rate > 0 && o.count == 0, kOk);
}

int shm_call(const Options& o) {
  const auto s = snapshot_of(o);
  const auto* v = find_service(s, o.name);
  if (!v) throw Failure{{Errc::not_found, "no service '" + o.name + "' in shm domain '" + o.domain + "'"}};
  const auto request = build(v->request_schema, v->qos.max_request_size, o.values);
  shm::Core core{o.domain, joining(o, "prime call")};
  // At least a millisecond: 0 would mean the service's own timeout. (main bounds --timeout.)
  const auto timeout = std::chrono::milliseconds{static_cast<std::int64_t>(std::ceil(o.timeout * 1000))};
  auto service = core.raw_chain(o.name, {.timeout = timeout});
  std::vector<std::byte> reply;
  auto done = service.call_in_place(
      [&](std::span<std::byte> to) {
        std::memcpy(to.data(), request.data(), request.size());
        return request.size();
      },
      [&](std::span<const std::byte> from) { reply.assign(from.begin(), from.end()); });
  if (!done) throw Failure{done.error()};
  const auto layout = layout_to_show(v->reply_schema, reply.size(), "the answer of '" + o.name + "'");
  if (o.json) {
    std::cout << (layout ? to_json(*layout, reply.data()) : quote(hex(reply, reply.size()))) << '\n';
  } else if (layout && layout->kind == Layout::Kind::record) {
    print_fields(std::cout, *layout, reply.data());
  } else if (layout) {
    std::cout << to_json(*layout, reply.data()) << '\n';
  } else {
    std::cout << "bytes: " << hex(reply) << '\n';
  }
  return kOk;
}

int shm_graph(const Options& o) {
  const auto s = snapshot_of(o);
  std::map<std::uint32_t, std::string> processes;  // pid -> the participants it runs
  for (const auto& p : s.participants)
    if (p.alive) processes[p.pid] += (processes[p.pid].empty() ? "" : ", ") + p.name;
  std::ostringstream out;
  out << "digraph prime {\n  rankdir=LR;\n  label=" << quote("shm domain " + o.domain) << ";\n";
  for (const auto& [pid, names] : processes)
    out << "  \"pid" << pid << "\" [shape=box, label=" << dot_label({names, "pid " + std::to_string(pid)}) << "];\n";
  for (const auto& t : s.topics) {
    out << "  " << quote("topic:" + t.name) << " [shape=ellipse, label=" << dot_label({t.name, short_type(t.type)}) << "];\n";
    if (t.publisher_pid) out << "  \"pid" << t.publisher_pid << "\" -> " << quote("topic:" + t.name) << " [label=\"publishes\"];\n";
    for (const auto pid : std::set<std::uint32_t>(t.subscriber_pids.begin(), t.subscriber_pids.end()))
      out << "  " << quote("topic:" + t.name) << " -> \"pid" << pid << "\" [label=\"subscribes\"];\n";
  }
  for (const auto& v : s.services) {
    out << "  " << quote("service:" + v.name) << " [shape=hexagon, label="
        << dot_label({v.name, short_type(v.request_type) + " -> " + short_type(v.reply_type)}) << "];\n";
    if (v.server_pid) out << "  " << quote("service:" + v.name) << " -> \"pid" << v.server_pid << "\" [label=\"served by\"];\n";
    for (const auto pid : std::set<std::uint32_t>(v.client_pids.begin(), v.client_pids.end()))
      out << "  \"pid" << pid << "\" -> " << quote("service:" + v.name) << " [label=\"calls\"];\n";
  }
  out << "}\n";
  std::cout << out.str();
  return kOk;
}

int shm_clean(const Options& o) {
  std::vector<std::string> domains;
  if (o.all) {
    for (const auto& d : shm::domains())
      if (d.unreadable.empty()) domains.push_back(d.name);
      else std::cerr << "prime: left domain '" << d.name << "' alone: " << d.unreadable << '\n';
  } else {
    snapshot_of(o);
    domains.push_back(o.domain);
  }
  std::size_t done = 0, failed = 0;
  std::string json = "[";
  for (const auto& d : domains) {
    for (const auto& line : shm::clean(d)) {
      const auto failure = failed_removal(line);
      ++(failure ? failed : done);
      if (o.json)
        json += (json.size() > 1 ? "," : "") + std::string{"{\"domain\":"} + quote(d) +
                (failure ? ",\"failed\":" + quote(*failure) : ",\"done\":" + quote(line)) + "}";
      else if (failure)
        std::cerr << "prime: " << d << ": " << *failure << '\n';
      else
        std::cout << d << ": " << line << '\n';
    }
  }
  if (o.json) std::cout << json << "]\n";
  else if (done + failed == 0) std::cout << "nothing to clean: no dead participant left anything\n";
  return failed > 0 ? int{kFailed} : int{kOk};
}

}  // namespace prime::tool
