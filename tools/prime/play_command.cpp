// prime play: the messages of one or more recordings, merged by their log
// times, published on their topics at the recorded timing (or X times
// that, or as fast as the readers take them).
#include "play_command.hpp"

#include <sys/prctl.h>

#include <algorithm>
#include <charconv>
#include <chrono>
#include <expected>
#include <functional>
#include <iostream>
#include <map>
#include <memory>
#include <optional>
#include <set>
#include <span>
#include <thread>

#include "prime/optimus.hpp"
#include "prime/record/merged_reader.hpp"
#include "prime/record/prime_metadata.hpp"
#include "prime/shm.hpp"
#include "json.hpp"
#include "stats.hpp"

namespace prime::tool {

namespace {

using namespace std::chrono_literals;
namespace rec = prime::record;

// One topic published: every file's channel of it leads here.
struct Played {
  std::string topic;
  std::string type;                  // as recorded: a Fingerprint's describe()
  std::optional<std::size_t> size;   // a typed Shm topic's sample size; none for bytes and Optimus messages
  std::optional<rec::CdrCodec> cdr;  // of its channels recorded in CDR (the type's, in every file)
  // Publishes a sample's bytes (a Shm topic's, or an Optimus message,
  // header and body) with its stamp.
  std::move_only_function<std::expected<void, Error>(std::span<const std::byte>, Clock::time_point)> publish;
  std::uint64_t sent = 0;
};

// Where the recordings play (a shared-memory domain, or an Optimus one):
// why a channel is not one it plays (none when it is), and its topic made
// for a channel (the first that plays on it) under the name it is
// published as.
struct PlayTarget {
  std::function<std::optional<std::string>(const rec::Channel&)> refuses;
  std::function<std::unique_ptr<Played>(const std::string& topic, const rec::Summary&, const rec::Channel&, const std::string& file)>
      open;
};

// --rate: a factor of the recorded speed; 0 for "max".
double rate_of(const std::string& text) {
  if (text == "max") return 0;
  double r = 0;
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), r);
  if (error != std::errc{} || end != text.data() + text.size() || !(r >= 1e-3 && r <= 1e6))
    throw Failure{{Errc::invalid_argument, "play: --rate '" + text + "' is neither max nor a factor from 0.001 to 1000000"}};
  return r;
}

std::map<std::string, std::string> remaps_of(const std::vector<std::string>& words) {
  std::map<std::string, std::string> out;
  for (const auto& w : words) {
    const auto at = w.find(":=");
    if (at == std::string::npos || at == 0 || at + 2 == w.size())
      throw Failure{{Errc::invalid_argument, "play: --remap '" + w + "' is not recorded:=published"}};
    out[w.substr(0, at)] = w.substr(at + 2);
  }
  return out;
}

// A channel's QoS entry, as the recorder wrote it, or `otherwise`.
std::size_t qos_entry(const rec::Channel& ch, const std::string& key, std::size_t otherwise) {
  const auto it = ch.metadata.find(key);
  std::size_t n = 0;
  if (it == ch.metadata.end()) return otherwise;
  const auto [end, error] = std::from_chars(it->second.data(), it->second.data() + it->second.size(), n);
  return error == std::errc{} && end == it->second.data() + it->second.size() ? n : otherwise;
}

// Until `t`, in steps so that Ctrl-C ends a long wait at once, the last
// stretch spun: a replay's timing error is then microseconds, not the
// scheduler's wake-up. False when Ctrl-C came first.
bool wait_until(Clock::time_point t) {
  constexpr auto kSpin = 50us;
  for (;;) {
    if (ctrl_c_pressed()) return false;
    const auto now = Clock::now();
    if (now >= t) return true;
    if (t - now > kSpin) std::this_thread::sleep_until(std::min(t - kSpin, now + 100ms));
  }
}


// A publisher for each topic the recordings hold (those `named`, or all),
// under its remapped name, made by the target. Per file, which topic each
// of its channels plays on.
struct Topics {
  std::map<std::string, std::unique_ptr<Played>> played;  // by the name published
  std::vector<std::map<std::uint16_t, Played*>> route;    // per file: channel to topic
};
Topics open_topics(const PlayTarget& target, const rec::MergedReader& files, const std::set<std::string>& named,
                   const std::map<std::string, std::string>& remaps) {
  std::map<std::string, std::unique_ptr<Played>> played;
  std::vector<std::map<std::uint16_t, Played*>> route(files.files());
  for (std::size_t f = 0; f < files.files(); ++f) {
    const auto& summary = files.file(f).summary();
    for (const auto& [id, ch] : summary.channels) {
      if (!named.empty() && !named.contains(ch.topic)) continue;
      if (const auto why = target.refuses(ch))
        throw Failure{{Errc::invalid_argument, "play: topic '" + ch.topic + "' of '" + files.path(f) + "' is in message encoding '" +
                                                   ch.message_encoding + "' (" + *why + "); --topics leaves it out"}};
      const auto remapped = remaps.find(ch.topic);
      const auto topic = remapped == remaps.end() ? ch.topic : remapped->second;
      const auto type = rec::recorded_type(summary, ch);
      if (const auto it = played.find(topic); it != played.end()) {
        if (it->second->type != type)
          throw Failure{{Errc::type_mismatch, "play: topic '" + topic + "' is recorded as " + it->second->type + " and, in '" +
                                                  files.path(f) + "', as " + type}};
        if (!it->second->cdr && it->second->size) it->second->cdr = rec::recorded_codec(ch, *it->second->size, files.path(f));
        route[f][id] = it->second.get();
        continue;
      }
      auto entry = target.open(topic, summary, ch, files.path(f));
      route[f][id] = entry.get();
      played.emplace(topic, std::move(entry));
    }
  }
  return {std::move(played), std::move(route)};
}

// Shared memory plays what was recorded from it: each topic made for the
// recorded type if none is there, refused if one of another type is.
PlayTarget shm_target(shm::Core& core) {
  auto refuses = [](const rec::Channel& ch) -> std::optional<std::string> {
    if (ch.message_encoding == "prime-raw" || ch.message_encoding == "cdr") return std::nullopt;
    return ch.message_encoding == "prime-optimus" ? "recorded from Optimus: play it with --redis" : "not Prime's";
  };
  auto open = [&core](const std::string& topic, const rec::Summary& summary, const rec::Channel& ch, const std::string& file) {
    const auto type = rec::recorded_type(summary, ch);
    const auto fingerprint = rec::recorded_fingerprint(summary, ch, file);
    std::optional<shm::Publisher<shm::Bytes>> publisher;
    if (fingerprint) {
      const shm::TopicQos qos{.capacity = qos_entry(ch, "capacity", 64),
                              .max_message_size = qos_entry(ch, "max_message_size", fingerprint->size),
                              .overflow = ch.metadata.contains("overflow") && ch.metadata.at("overflow") == "block"
                                              ? Overflow::block
                                              : Overflow::drop_oldest};
      const auto description = ch.metadata.find(rec::kDescriptionEntry);
      const auto schema = summary.schemas.find(ch.schema_id);
      const auto text = description != ch.metadata.end()                                          ? description->second
                        : schema != summary.schemas.end() && schema->second.encoding == "prime" ? schema->second.data
                                                                                                  : std::string{};
      publisher.emplace(core.raw_publisher(topic, *fingerprint, text, qos));
    } else {
      // Recorded without its fingerprint: only onto a topic its readers opened, of the type recorded.
      const auto snapshot = core.registry();
      const auto live = std::ranges::find(snapshot.topics, topic, &shm::RegistrySnapshot::Topic::name);
      if (live == snapshot.topics.end())
        throw Failure{{Errc::not_found, "play: '" + file + "' holds no fingerprint of the type of '" + ch.topic +
                                            "': start a reader of '" + topic + "' first, so that the topic exists"}};
      if (live->type != type)
        throw Failure{{Errc::type_mismatch, "play: topic '" + topic + "' carries " + live->type + ", recorded as " + type}};
      publisher.emplace(core.raw_publisher(topic));
    }
    const bool bytes = fingerprint && *fingerprint == Fingerprint::of<shm::Bytes>();
    const auto size = fingerprint && !bytes ? std::optional{fingerprint->size} : std::nullopt;
    // On a `block` topic whose readers are behind, a publish waits for
    // them (the timing slips rather than a sample being lost).
    return std::make_unique<Played>(Played{topic, type, size, size ? rec::recorded_codec(ch, *size, file) : std::nullopt,
                                           [p = std::move(*publisher)](std::span<const std::byte> data, Clock::time_point stamp) mutable {
                                             return p.publish(data, stamp);
                                           }});
  };
  return {refuses, open};
}

// Optimus plays what was recorded from it: each message as the recorder
// read it from the source's stream (header and body), checked against
// the source's type, onto a source registered with the recorded type.
PlayTarget optimus_target(optimus::Core& core) {
  auto refuses = [](const rec::Channel& ch) -> std::optional<std::string> {
    if (ch.message_encoding == "prime-optimus") return std::nullopt;
    return ch.message_encoding == "prime-raw" || ch.message_encoding == "cdr" ? "recorded from shared memory: play it without --redis"
                                                                              : "not Prime's";
  };
  auto open = [&core](const std::string& topic, const rec::Summary& summary, const rec::Channel& ch, const std::string& file) {
    // The type as the registry keeps it, from the file: checked before it
    // goes into the registry, where it would lock out the real type's
    // endpoints if it were forged.
    const auto type = rec::recorded_type(summary, ch);
    const auto record = ch.metadata.find(rec::kOptimusTypeEntry);
    if (record == ch.metadata.end())
      throw Failure{{Errc::damaged, "play: '" + file + "' keeps no Optimus type record for '" + ch.topic + "' (its channel's '" +
                                        rec::kOptimusTypeEntry + "' entry: recorded by an older prime?)"}};
    const auto& r = record->second;  // "<hash> <description>": Core::raw_publisher checks the hash
    if (r.size() < 18 || r[16] != ' ' || r.substr(17) != type)
      throw Failure{{Errc::damaged, "play: '" + file + "': the Optimus type record of '" + ch.topic + "' is " + quote(r) +
                                        ", not a fingerprint hash and the recorded type " + quote(type)}};
    return std::make_unique<Played>(
        Played{topic, type, std::nullopt, std::nullopt,
               [p = core.raw_publisher(topic, r)](std::span<const std::byte> data, Clock::time_point stamp) {
                 return p.publish({reinterpret_cast<const char*>(data.data()), data.size()}, stamp);
               }});
  };
  return {refuses, open};
}

// The recordings of `p`, checked, then played into the target that `join`
// joins.
int play(const PlayOptions& p, const std::function<PlayTarget()>& join) {
  const auto rate = rate_of(p.rate);
  const auto remaps = remaps_of(p.remaps);
  const bool keep_stamps = p.stamps == "keep";
  rec::MergedReader files{p.files};

  std::set<std::string> named(p.topics.begin(), p.topics.end());
  std::set<std::string> recorded;
  for (std::size_t f = 0; f < files.files(); ++f)
    for (const auto& [id, ch] : files.file(f).summary().channels) recorded.insert(ch.topic);
  for (const auto& t : named)
    if (!recorded.contains(t)) throw Failure{{Errc::not_found, "play: no topic '" + t + "' in the recordings given"}};
  for (const auto& [from, to] : remaps)
    if (!recorded.contains(from)) throw Failure{{Errc::not_found, "play: --remap of '" + from + "': no such topic in the recordings given"}};

  const auto from = files.start_time() + static_cast<std::uint64_t>(p.start * 1e9);
  if (p.start > 0 && from > files.end_time())
    throw Failure{{Errc::invalid_argument, "play: --start " + fixed(p.start, 3) + " s is past the recordings' end (" +
                                               fixed(static_cast<double>(files.end_time() - files.start_time()) / 1e9, 3) + " s)"}};
  const auto to = p.duration > 0 ? from + static_cast<std::uint64_t>(p.duration * 1e9) : std::numeric_limits<std::uint64_t>::max();
  const auto span = std::min(to, files.end_time()) - from;  // of the recording, in ns: one pass

  auto [played, route] = open_topics(join(), files, named, remaps);
  std::vector<std::int64_t> steady_to_unix(files.files());
  std::vector<std::set<std::uint16_t>> cdr_channels(files.files());  // per file: the channels recorded in CDR
  for (std::size_t f = 0; f < files.files(); ++f) {
    steady_to_unix[f] = rec::steady_to_unix_ns(files.file(f).summary(), files.path(f));
    for (const auto& [id, ch] : files.file(f).summary().channels)
      if (ch.message_encoding == "cdr") cdr_channels[f].insert(id);
  }
  if (played.empty()) throw Failure{{Errc::not_found, "play: the recordings given hold no topic"}};

  finish_on_ctrl_c();
  ::prctl(PR_SET_TIMERSLACK, 1UL);  // wake-ups when asked, not up to 50 µs later
  auto wanted = [&](std::size_t f, std::uint16_t channel) { return route[f].contains(channel); };
  const auto started = Clock::now();
  auto pass_start = started;
  do {
    files.seek(from, to, wanted);
    auto m = files.next();
    if (!m) break;  // nothing in the span asked for: a loop would only spin
    // Timed from the first sample in hand (its chunk read), or later if
    // the pass before ran late.
    pass_start = std::max(pass_start, Clock::now());
    for (; m; m = files.next()) {
      auto& t = *route[m->file].at(m->message.channel_id);
      if (t.cdr && cdr_channels[m->file].contains(m->message.channel_id))
        m->message.data = t.cdr->decode(m->message.data, "recording '" + files.path(m->file) + "': a sample of '" + t.topic + "'");
      const auto& data = m->message.data;
      if (t.size && data.size() != *t.size)
        throw Failure{{Errc::damaged, "recording '" + files.path(m->file) + "': a sample of '" + t.topic + "' is " +
                                          std::to_string(data.size()) + " bytes, not the " + std::to_string(*t.size) + " of " + t.type}};
      const auto offset = std::chrono::nanoseconds{m->message.log_time - from};
      if (rate > 0 && !wait_until(pass_start + std::chrono::duration_cast<Clock::duration>(offset / rate))) break;
      const auto stamp = keep_stamps ? Clock::time_point{std::chrono::nanoseconds{static_cast<std::int64_t>(m->message.log_time) -
                                                                                 steady_to_unix[m->file]}}
                                     : Clock::now();
      if (auto sent = t.publish(data, stamp); !sent)
        throw Failure{{sent.error().code, "play: recording '" + files.path(m->file) + "': " + sent.error().message}};
      ++t.sent;
    }
    if (rate > 0) pass_start += std::chrono::duration_cast<Clock::duration>(std::chrono::nanoseconds{span} / rate);
  } while (p.loop && !ctrl_c_pressed());

  const auto took = std::chrono::duration<double>(Clock::now() - started).count();
  std::uint64_t total = 0;
  for (const auto& [name, t] : played) {
    std::cerr << "prime: played " << t->sent << " samples on '" << name << "'\n";
    total += t->sent;
  }
  std::cerr << "prime: played " << total << " samples in " << fixed(took, 3) << " s\n";
  return after_ctrl_c(p.loop, int{kOk});
}

}  // namespace

int shm_play(const Options& o, const PlayOptions& p) {
  std::optional<shm::Core> core;
  return play(p, [&] {
    // A publisher like any other: it sets the domain up if no one has.
    auto joined = shm::access_of(o.domain) ? joining(o, "prime play") : shm::DomainOptions{.participant = "prime play"};
    joined.only_if_alive = false;
    return shm_target(core.emplace(o.domain, joined));
  });
}

int optimus_play(const Options& o, const PlayOptions& p) {
  std::optional<optimus::Core> core;
  return play(p, [&] { return optimus_target(core.emplace(optimus_options(o))); });
}

}  // namespace prime::tool
