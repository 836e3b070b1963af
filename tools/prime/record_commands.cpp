// prime record: topics of a shared-memory domain, read as the domain's
// observer (a `block` publisher never waits for it), written into an MCAP
// file; prime record info: what a recording holds.
#include "record_commands.hpp"

#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cmath>
#include <filesystem>
#include <iostream>
#include <map>
#include <memory>
#include <regex>
#include <set>
#include <thread>

#include "json.hpp"
#include "prime/record/cdr.hpp"
#include "prime/record/mcap_reader.hpp"
#include "prime/record/mcap_writer.hpp"
#include "prime/record/prime_metadata.hpp"
#include "prime/record/recorder.hpp"
#include "prime/record/snapshot_recorder.hpp"
#include "prime/shm.hpp"
#include "stats.hpp"
#include "table.hpp"

namespace prime::tool {

namespace {

using namespace std::chrono_literals;
namespace rec = prime::record;

rec::Compression compression_named(const std::string& name) {
  if (name == "none") return rec::Compression::none;
  if (name == "lz4") return rec::Compression::lz4;
  if (name == "zstd") return rec::Compression::zstd;
  throw Failure{{Errc::invalid_argument, "compression '" + name + "' is none of none, lz4, zstd"}};
}

// One topic being recorded: its reader in the tools' slot, its channel.
struct Recorded {
  std::string topic;
  Reader<shm::View<shm::Bytes>> reader;
  std::size_t index;  // the recorder's
  std::size_t capacity;
  std::optional<rec::CdrCodec> cdr;  // its samples written as CDR, through `encoded`
  std::vector<std::byte> encoded;
  std::uint64_t written = 0;
  std::uint64_t lost = 0;
};

// Set by SIGUSR1: write a snapshot.
volatile std::sig_atomic_t snapshot_asked = 0;

}  // namespace

int shm_record(const Options& o, const RecordOptions& r) {
  if (r.out.empty()) throw Failure{{Errc::invalid_argument, "record: no file given (-o FILE.mcap)"}};
  if (r.topics.empty() && !r.all) throw Failure{{Errc::invalid_argument, "record: name the topics, or --all"}};
  if (!r.topics.empty() && r.all) throw Failure{{Errc::invalid_argument, "record: topics named and --all: one or the other"}};
  std::optional<std::regex> exclude;
  if (!r.exclude.empty()) {
    try {
      exclude.emplace(r.exclude, std::regex::extended);
    } catch (const std::regex_error& e) {
      throw Failure{{Errc::invalid_argument, "record: --exclude '" + r.exclude + "' is no regular expression: " + e.what()}};
    }
  }
  const auto snapshot = snapshot_of(o);
  shm::Core core{o.domain, joining(o, "prime record")};
  const rec::RecorderOptions options{
      .file = {.compression = compression_named(r.compression), .chunk_size = r.chunk_size, .profile = ""},
      .max_size = r.max_size,
      .max_duration = static_cast<std::uint64_t>(r.max_duration * 1e9)};
  // Every sample into the file (or a series), or, with --snapshot, the
  // last seconds in memory, into a file of a series at each SIGUSR1.
  rec::SnapshotRecorder* snapshots = nullptr;
  std::unique_ptr<rec::Sink> sink;
  if (r.snapshot > 0) {
    auto s = std::make_unique<rec::SnapshotRecorder>(r.out, options, static_cast<std::uint64_t>(r.snapshot * 1e9));
    snapshots = s.get();
    sink = std::move(s);
  } else {
    sink = std::make_unique<rec::Recorder>(r.out, options);
  }
  auto& file = *sink;
  // Stamps are steady_clock (one clock for every process of the machine):
  // written as Unix time, by one offset taken now and kept in the file.
  const auto steady_to_unix = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                  std::chrono::system_clock::now().time_since_epoch() - Clock::now().time_since_epoch())
                                  .count();
  file.add_metadata({rec::kClockMetadata, {{"steady_to_unix_ns", std::to_string(steady_to_unix)}}});
  std::vector<std::unique_ptr<Recorded>> recorded;
  std::set<std::string> known;
  // Opens what is to be recorded and is not yet: every topic named must be
  // there at the start; with --all, topics that appear later join.
  auto open = [&](const shm::RegistrySnapshot& s, bool at_start) {
    auto wanted = [&](const std::string& name) {
      if (r.all) return !(exclude && std::regex_search(name, *exclude));
      return std::ranges::find(r.topics, name) != r.topics.end();
    };
    if (at_start)
      for (const auto& name : r.topics)
        if (std::ranges::none_of(s.topics, [&](const auto& t) { return t.name == name; }))
          throw Failure{{Errc::not_found, "no topic '" + name + "' in shm domain '" + o.domain + "'"}};
    for (const auto& t : s.topics) {
      if (known.contains(t.name) || !wanted(t.name)) continue;
      known.insert(t.name);
      auto metadata = rec::fingerprint_metadata(t.fingerprint);
      metadata.insert({{rec::kTypeEntry, t.type},
                       {"capacity", std::to_string(t.qos.capacity)},
                       {"max_message_size", std::to_string(t.qos.max_message_size)},
                       {"overflow", t.qos.overflow == Overflow::block ? "block" : "drop_oldest"}});
      // A described type as ROS 2 says it (ros2msg, CDR), which tools that
      // know ROS 2 decode field by field; any other as its bytes, under a
      // schema that names it.
      auto cdr = t.fingerprint == Fingerprint::of<shm::Bytes>() ? std::nullopt : rec::CdrCodec::of(t.schema, t.fingerprint.size);
      std::size_t topic = 0;
      if (cdr) {
        metadata[rec::kDescriptionEntry] = t.schema;
        const auto name = rec::ros2_name(read_text(t.fingerprint.name));
        topic = file.add_topic({0, name, "ros2msg", cdr->definition(name)}, {0, 0, t.name, "cdr", metadata});
      } else {
        topic = file.add_topic({0, t.type, "prime", t.schema}, {0, 0, t.name, "prime-raw", metadata});
      }
      recorded.push_back(std::make_unique<Recorded>(Recorded{t.name, core.observe(t.name), topic, t.qos.capacity, std::move(cdr), {}}));
    }
  };
  open(snapshot, true);
  if (recorded.empty()) std::cerr << "prime: no topic to record yet; waiting for some (--all)\n";

  finish_on_ctrl_c();
  if (snapshots) {
    std::signal(SIGUSR1, [](int) { snapshot_asked = 1; });
    std::cerr << "prime: keeping the last " << r.snapshot << " s in memory; kill -USR1 " << ::getpid() << " writes them\n";
  }
  const auto start = Clock::now();
  const auto until = o.duration > 0 ? start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o.duration))
                                    : Clock::time_point::max();
  std::uint64_t total = 0;
  auto next_look = start + 1s;
  // What `t` has published and is not yet read, up to `most` samples: its
  // one view at a time (the tools' slot holds one), copied into the
  // writer's queue, then let go. Whether there was any.
  auto read_some = [&](Recorded& t, std::size_t most) {
    bool any = false;
    for (std::size_t k = 0; k < most && (o.count == 0 || total < o.count); ++k) {
      auto sample = t.reader.try_read();
      if (!sample) break;
      const auto arrived = Clock::now();
      const auto log_time = static_cast<std::uint64_t>(sample->stamp.time_since_epoch().count() + steady_to_unix);
      const auto publish_time = static_cast<std::uint64_t>(arrived.time_since_epoch().count() + steady_to_unix);
      const auto bytes = sample->value.bytes();
      if (t.cdr) t.cdr->encode(bytes, t.encoded);
      file.write(t.index, static_cast<std::uint32_t>(sample->value.sequence()), log_time, publish_time,
                 t.cdr ? std::span<const std::byte>{t.encoded} : bytes);
      ++t.written;
      ++total;
      any = true;
    }
    if (const auto lost = t.reader.lost(); lost != t.lost) file.lost(t.index, t.lost = lost);
    return any;
  };
  while (!ctrl_c_pressed() && Clock::now() < until && (o.count == 0 || total < o.count)) {
    bool any = false;
    for (auto& t : recorded) any = read_some(*t, 256) || any;
    if (snapshots && snapshot_asked) {
      snapshot_asked = 0;
      const auto span = static_cast<double>(snapshots->held_span()) / 1e9;
      const auto [name, messages] = snapshots->take();
      std::cerr << "prime: " << name << ": the last " << fixed(span, 3) << " s, " << messages << " samples\n";
    }
    if (r.all && Clock::now() >= next_look) {
      open(core.registry(), false);
      next_look = Clock::now() + 1s;
    }
    if (!any) {
      file.flush();
      std::this_thread::sleep_for(100us);
    }
  }
  // Stopped: what was published by now is recorded too (a ring's worth at
  // most, so a publisher flat out does not keep it going).
  for (auto& t : recorded) read_some(*t, t->capacity);
  file.close();
  for (const auto& t : recorded)
    std::cerr << "prime: recorded " << t->written << " samples of '" << t->topic << "', lost " << t->lost << '\n';
  const auto files = file.files();
  if (files.empty()) {
    std::cerr << "prime: no snapshot was asked for: nothing written\n";
    return after_ctrl_c(o.duration <= 0 && o.count == 0, int{kOk});
  }
  std::cerr << "prime: " << (files.size() == 1 ? files.front() : std::to_string(files.size()) + " files, " + files.front() + " to " + files.back())
            << ": " << file.bytes_written() << " bytes\n";
  const bool open_ended = o.duration <= 0 && o.count == 0;
  return after_ctrl_c(open_ended, int{kOk});
}

int record_info(const Options& o, const std::string& path) {
  const rec::McapReader reader{path};
  const auto& s = reader.summary();
  std::map<std::string, std::string> losses;
  for (const auto& m : s.metadata)
    if (m.name == rec::kLossesMetadata) losses = m.values;
  const auto& st = s.statistics;
  const double seconds = st.message_count > 1 ? static_cast<double>(st.message_end_time - st.message_start_time) / 1e9 : 0.0;
  std::set<std::string> compressions;
  std::uint64_t compressed = 0, uncompressed = 0;
  for (const auto& c : s.chunks) {
    compressions.insert(c.compression.empty() ? "none" : c.compression);
    compressed += c.compressed_size;
    uncompressed += c.uncompressed_size;
  }
  std::string compression;
  for (const auto& c : compressions) compression += (compression.empty() ? "" : ",") + c;
  auto count_of = [&](std::uint16_t id) {
    const auto it = st.channel_message_counts.find(id);
    return it == st.channel_message_counts.end() ? std::uint64_t{0} : it->second;
  };
  auto type_of = [&](const rec::Channel& ch) { return rec::recorded_type(s, ch); };
  auto lost_of = [&](const rec::Channel& ch) -> std::string {
    const auto it = losses.find(ch.topic);
    return it == losses.end() ? std::string{"?"} : it->second;
  };
  if (o.json) {
    std::cout << "{\"file\":" << quote(path) << ",\"bytes\":" << s.file_size << ",\"complete\":" << (reader.complete() ? "true" : "false")
              << ",\"library\":" << quote(s.library) << ",\"messages\":" << st.message_count << ",\"chunks\":" << s.chunks.size()
              << ",\"compression\":" << quote(compression) << ",\"compressed_bytes\":" << compressed
              << ",\"uncompressed_bytes\":" << uncompressed << ",\"start_ns\":" << st.message_start_time
              << ",\"end_ns\":" << st.message_end_time << ",\"duration_s\":" << fixed(seconds, 6) << ",\"topics\":[";
    bool first = true;
    for (const auto& [id, ch] : s.channels) {
      const auto n = count_of(id);
      std::cout << (first ? "" : ",") << "{\"topic\":" << quote(ch.topic) << ",\"type\":" << quote(type_of(ch))
                << ",\"messages\":" << n << ",\"rate\":" << fixed(seconds > 0 ? static_cast<double>(n) / seconds : 0.0)
                << ",\"lost\":" << (losses.contains(ch.topic) ? losses.at(ch.topic) : "null") << "}";
      first = false;
    }
    std::cout << "]}\n";
    return kOk;
  }
  std::cout << "file:        " << path << " (" << s.file_size << " bytes" << (reader.complete() ? "" : ", cut short: read up to its last complete chunk") << ")\n"
            << "written by:  " << (s.library.empty() ? "?" : s.library) << "\n"
            << "messages:    " << st.message_count << " in " << s.chunks.size() << " chunks\n"
            << "duration:    " << fixed(seconds, 3) << " s\n"
            << "compression: " << (compression.empty() ? "none" : compression) << " (" << compressed << " of "
            << uncompressed << " bytes)\n";
  Table table{std::vector<std::string>{"TOPIC", "TYPE", "MESSAGES", "RATE/s", "LOST"}};
  for (const auto& [id, ch] : s.channels) {
    const auto n = count_of(id);
    table.add({ch.topic, type_of(ch), std::to_string(n), fixed(seconds > 0 ? static_cast<double>(n) / seconds : 0.0),
               lost_of(ch)});
  }
  table.print(std::cout);
  return kOk;
}

int record_recover(const std::string& path, const std::string& out) {
  if (out.empty()) throw Failure{{Errc::invalid_argument, "record recover: no file to write given (-o FILE.mcap)"}};
  std::error_code ignored;
  if (std::filesystem::equivalent(path, out, ignored))
    throw Failure{{Errc::invalid_argument, "record recover: '" + out + "' is the recording itself: write it elsewhere"}};
  const rec::McapReader reader{path};
  const auto& s = reader.summary();
  const auto compression = s.chunks.empty() || s.chunks.front().compression.empty() ? rec::Compression::none
                           : s.chunks.front().compression == "lz4"                   ? rec::Compression::lz4
                                                                                      : rec::Compression::zstd;
  rec::McapWriter file{out, {.compression = compression, .chunk_size = 1 << 20, .profile = s.profile}};
  std::map<std::uint16_t, std::uint16_t> schemas, channels;
  for (const auto& [id, schema] : s.schemas) schemas[id] = file.add_schema(schema.name, schema.encoding, schema.data);
  for (const auto& [id, ch] : s.channels)
    channels[id] = file.add_channel(ch.schema_id == 0 ? 0 : schemas.at(ch.schema_id), ch.topic, ch.message_encoding, ch.metadata);
  for (const auto& m : s.metadata) file.add_metadata(m.name, m.values);
  std::uint64_t copied = 0, orphans = 0;
  reader.for_each_message([&](const rec::Message& m) {
    const auto to = channels.find(m.channel_id);
    if (to == channels.end()) {  // of a channel the file never described: nothing could read it
      ++orphans;
      return;
    }
    file.write(to->second, m.sequence, m.log_time, m.publish_time, m.data);
    ++copied;
  });
  file.close();
  std::cerr << "prime: " << path << (reader.complete() ? " was complete already" : " was cut short") << "; " << copied
            << " messages of " << s.channels.size() << " topics in " << s.chunks.size() << " complete chunks written to "
            << out << " with an index and a summary";
  if (orphans > 0) std::cerr << "; " << orphans << " messages of channels it never described left out";
  std::cerr << '\n';
  return kOk;
}

}  // namespace prime::tool
