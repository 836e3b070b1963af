// prime record: topics of a shared-memory domain, read as the domain's
// observer (a `block` publisher never waits for it), written into an MCAP
// file; prime record info: what a recording holds.
#include "record_commands.hpp"

#include <unistd.h>

#include <chrono>
#include <csignal>
#include <cmath>
#include <filesystem>
#include <functional>
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
#include "prime/optimus/inspect.hpp"
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

// Set by SIGUSR1: write a snapshot.
volatile std::sig_atomic_t snapshot_asked = 0;

// One topic being recorded, of either medium: how its samples are read
// (up to `most` of what is there now, each handed to `write`; whether
// there was any), and what was written and lost of it.
struct Recorded {
  std::string topic;
  std::size_t index;  // the sink's
  std::size_t capacity;  // what its ring holds (or what is read at most): read once more at the end
  bool ring;             // a shared-memory topic: a loss is a sample its ring overwrote before it was read
  std::function<bool(Recorded& self, std::size_t most)> read;
  std::uint64_t written = 0;
  std::uint64_t lost = 0;
};

// What every recording shares, whatever the medium: the options checked,
// the sink (every sample into a file or a series, or with --snapshot the
// last seconds in memory), the clock, the loop until Ctrl-C, --duration
// or -n, and the report.
class Recording {
 public:
  Recording(const Options& o, const RecordOptions& r) : o_{o}, r_{r} {
    if (r.out.empty()) throw Failure{{Errc::invalid_argument, "record: no file given (-o FILE.mcap)"}};
    if (r.topics.empty() && !r.all) throw Failure{{Errc::invalid_argument, "record: name the topics, or --all"}};
    if (!r.topics.empty() && r.all) throw Failure{{Errc::invalid_argument, "record: topics named and --all: one or the other"}};
    if (!r.exclude.empty()) {
      try {
        exclude_.emplace(r.exclude, std::regex::extended);
      } catch (const std::regex_error& e) {
        throw Failure{{Errc::invalid_argument, "record: --exclude '" + r.exclude + "' is no regular expression: " + e.what()}};
      }
    }
  }

  // Whether topic `name` is one to record.
  [[nodiscard]] bool wanted(const std::string& name) const {
    if (r_.all) return !(exclude_ && std::regex_search(name, *exclude_));
    return std::ranges::find(r_.topics, name) != r_.topics.end();
  }
  // Opens the sink: after the domain is found, so a missing one makes no file.
  void begin() {
    const rec::RecorderOptions options{
        .file = {.compression = compression_named(r_.compression), .chunk_size = r_.chunk_size, .profile = ""},
        .max_size = r_.max_size,
        .max_duration = static_cast<std::uint64_t>(r_.max_duration * 1e9)};
    if (r_.snapshot > 0) {
      auto s = std::make_unique<rec::SnapshotRecorder>(r_.out, options, static_cast<std::uint64_t>(r_.snapshot * 1e9));
      snapshots_ = s.get();
      sink_ = std::move(s);
    } else {
      sink_ = std::make_unique<rec::Recorder>(r_.out, options);
    }
    sink_->add_metadata({rec::kClockMetadata, {{"steady_to_unix_ns", std::to_string(steady_to_unix_)}}});
  }
  rec::Sink& sink() { return *sink_; }
  // A topic to read by `read` (given its index, from add_topic).
  void add(std::string topic, std::size_t index, std::size_t capacity, bool ring, std::function<bool(Recorded&, std::size_t)> read) {
    topics_.push_back(std::make_unique<Recorded>(Recorded{std::move(topic), index, capacity, ring, std::move(read)}));
  }
  [[nodiscard]] bool empty() const { return topics_.empty(); }
  // Whether -n leaves room for another sample.
  [[nodiscard]] bool more() const { return o_.count == 0 || total_ < o_.count; }

  // One sample of topic `t`, stamped `stamp` (steady_clock, as published),
  // arriving now.
  void write(Recorded& t, std::uint32_t sequence, Clock::time_point stamp, std::vector<std::byte> data) {
    const auto log_time = static_cast<std::uint64_t>(stamp.time_since_epoch().count() + steady_to_unix_);
    const auto publish_time = static_cast<std::uint64_t>(Clock::now().time_since_epoch().count() + steady_to_unix_);
    sink_->write(t.index, sequence, log_time, publish_time, std::move(data));
    ++t.written;
    ++total_;
  }
  void lost(Recorded& t, std::uint64_t so_far) {
    if (so_far != t.lost) sink_->lost(t.index, t.lost = so_far);
  }
  // Reads until Ctrl-C, --duration or -n; `look` (every second, with
  // --all) opens the topics that appeared; `nap` waits when nothing came.
  int run(const std::function<void()>& look, const std::function<void()>& nap) {
    // Said once Ctrl-C is caught: from then on it ends the recording whole.
    finish_on_ctrl_c();
    if (topics_.empty())
      std::cerr << "prime: no topic to record yet; waiting for some (--all)\n";
    else if (!snapshots_)
      std::cerr << "prime: recording " << topics_.size() << (topics_.size() == 1 ? " topic" : " topics") << " into " << r_.out
                << "; Ctrl-C ends it\n";
    if (snapshots_) {
      std::signal(SIGUSR1, [](int) { snapshot_asked = 1; });
      std::cerr << "prime: keeping the last " << r_.snapshot << " s in memory; kill -USR1 " << ::getpid() << " writes them\n";
    }
    const auto start = Clock::now();
    const auto until = o_.duration > 0 ? start + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>(o_.duration))
                                       : Clock::time_point::max();
    auto next_look = start + 1s;
    while (!ctrl_c_pressed() && Clock::now() < until && more()) {
      bool any = false;
      for (auto& t : topics_) any = t->read(*t, 256) || any;
      if (snapshots_ && snapshot_asked) {
        snapshot_asked = 0;
        const auto span = static_cast<double>(snapshots_->held_span()) / 1e9;
        const auto [name, messages] = snapshots_->take();
        std::cerr << "prime: " << name << ": the last " << fixed(span, 3) << " s, " << messages << " samples\n";
      }
      if (r_.all && Clock::now() >= next_look) {
        look();
        next_look = Clock::now() + 1s;
      }
      if (!any) {
        sink_->flush();
        nap();
      }
    }
    // Stopped: what was published by now is recorded too (a ring's worth
    // at most, so a publisher flat out does not keep it going).
    for (auto& t : topics_) t->read(*t, t->capacity);
    sink_->close();
    const auto seconds = std::chrono::duration<double>(Clock::now() - start).count();
    for (const auto& t : topics_) {
      std::cerr << "prime: recorded " << t->written << " samples of '" << t->topic << "', lost " << t->lost << '\n';
      if (t->ring && t->lost > 0) std::cerr << "prime: " << why_lost(*t, seconds) << '\n';
    }
    const bool open_ended = o_.duration <= 0 && o_.count == 0;
    const auto files = sink_->files();
    if (files.empty()) {
      std::cerr << "prime: no snapshot was asked for: nothing written\n";
      return after_ctrl_c(open_ended, int{kOk});
    }
    std::cerr << "prime: "
              << (files.size() == 1 ? files.front() : std::to_string(files.size()) + " files, " + files.front() + " to " + files.back())
              << ": " << sink_->bytes_written() << " bytes\n";
    return after_ctrl_c(open_ended, int{kOk});
  }

 private:
  // What a ring's losses say: the time its ring lasts at the topic's mean
  // rate, against how long a reader may be kept from its CPU
  // (docs/performance.md, "Recording"), and a capacity that lasts 10 ms.
  static std::string why_lost(const Recorded& t, double seconds) {
    const auto rate = static_cast<double>(t.written + t.lost) / std::max(seconds, 1e-3);
    const auto lasts_ms = static_cast<double>(t.capacity) / rate * 1e3;
    std::size_t enough = 2;
    while (static_cast<double>(enough) < rate / 100 || enough <= t.capacity) enough *= 2;
    return "'" + t.topic + "' lost samples its ring overwrote before they were read: it holds " + std::to_string(t.capacity) +
           ", " + fixed(lasts_ms, 2) + " ms at its mean rate of " + fixed(rate, 0) + " Hz, and a reader is " +
           "sometimes kept from its CPU longer than that; a topic capacity of " + std::to_string(enough) +
           " gives it 10 ms or more";
  }

  const Options& o_;
  const RecordOptions& r_;
  std::optional<std::regex> exclude_;
  // Stamps are steady_clock (one clock for every process of the machine):
  // written as Unix time, by one offset taken now and kept in the file.
  const std::int64_t steady_to_unix_ = std::chrono::duration_cast<std::chrono::nanoseconds>(
                                           std::chrono::system_clock::now().time_since_epoch() - Clock::now().time_since_epoch())
                                           .count();
  std::unique_ptr<rec::Sink> sink_;
  rec::SnapshotRecorder* snapshots_ = nullptr;
  std::vector<std::unique_ptr<Recorded>> topics_;
  std::uint64_t total_ = 0;
};

}  // namespace

int shm_record(const Options& o, const RecordOptions& r) {
  Recording recording{o, r};
  const auto snapshot = snapshot_of(o);
  shm::Core core{o.domain, joining(o, "prime record")};
  for (const auto& name : r.topics)
    if (std::ranges::none_of(snapshot.topics, [&](const auto& t) { return t.name == name; }))
      throw Failure{{Errc::not_found, "no topic '" + name + "' in shm domain '" + o.domain + "'"}};
  recording.begin();
  // Each topic's reader in the tools' slot (so no `block` publisher waits
  // for it), and what turns its views into messages.
  struct Reading {
    Reader<shm::View<shm::Bytes>> reader;
    std::optional<rec::CdrCodec> cdr;  // its samples written as CDR
  };
  std::vector<std::unique_ptr<Reading>> readings;
  std::set<std::string> known;
  // Opens what is to be recorded and is not yet (with --all, topics that
  // appear later join).
  auto open = [&](const shm::RegistrySnapshot& s) {
    for (const auto& t : s.topics) {
      if (known.contains(t.name) || !recording.wanted(t.name)) continue;
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
      std::size_t index = 0;
      if (cdr) {
        metadata[rec::kDescriptionEntry] = t.schema;
        const auto name = rec::ros2_name(read_text(t.fingerprint.name));
        index = recording.sink().add_topic({0, name, "ros2msg", cdr->definition(name)}, {0, 0, t.name, "cdr", metadata});
      } else {
        index = recording.sink().add_topic({0, t.type, "prime", t.schema}, {0, 0, t.name, "prime-raw", metadata});
      }
      auto& reading = *readings.emplace_back(std::make_unique<Reading>(Reading{core.observe(t.name), std::move(cdr)}));
      // Its one view at a time (the tools' slot holds one): copied (or
      // encoded) into a message for the writer's queue, then let go.
      recording.add(t.name, index, t.qos.capacity, true, [&recording, &reading](Recorded& t, std::size_t most) {
        bool any = false;
        for (std::size_t k = 0; k < most && recording.more(); ++k) {
          auto sample = reading.reader.try_read();
          if (!sample) break;
          const auto bytes = sample->value.bytes();
          std::vector<std::byte> message;
          if (reading.cdr)
            reading.cdr->encode(bytes, message);
          else
            message.assign(bytes.begin(), bytes.end());
          recording.write(t, static_cast<std::uint32_t>(sample->value.sequence()), sample->stamp, std::move(message));
          any = true;
        }
        recording.lost(t, reading.reader.lost());
        return any;
      });
    }
  };
  open(snapshot);
  return recording.run([&] { open(core.registry()); }, [] { std::this_thread::sleep_for(100us); });
}

int optimus_record(const Options& o, const RecordOptions& r) {
  Recording recording{o, r};
  auto inspector = optimus_inspector(o);
  const auto sources = inspector.sources();
  for (const auto& name : r.topics)
    if (std::ranges::none_of(sources, [&](const auto& s) { return s.name == name; }))
      throw Failure{{Errc::not_found, "no source '" + name + "' in Optimus domain '" + o.domain + "'"}};
  recording.begin();
  // Each source's stream from now on, read through one connection. Its
  // entries are recorded as Optimus sent them (its 16-byte header, then
  // the body: the type's bytes or MessagePack): message encoding
  // "prime-optimus". A gap in the stream's sequence numbers is what was
  // trimmed from it before the recorder read it: lost.
  struct Reading {
    optimus::Inspector::Tail tail;
    std::optional<std::uint64_t> last;
    std::uint64_t lost = 0;
  };
  std::vector<std::unique_ptr<Reading>> readings;
  std::set<std::string> known;
  auto open = [&](const std::vector<optimus::SourceSummary>& all) {
    for (const auto& s : all) {
      if (known.contains(s.name) || !recording.wanted(s.name)) continue;
      known.insert(s.name);
      const auto index = recording.sink().add_topic(
          {0, s.type, "", ""}, {0, 0, s.name, "prime-optimus", {{rec::kTypeEntry, s.type}, {rec::kOptimusTypeEntry, s.record}, {"medium", "optimus"}}});
      auto& reading = *readings.emplace_back(std::make_unique<Reading>(Reading{inspector.tail(s.name), {}, 0}));
      recording.add(s.name, index, 100, false, [&recording, &reading](Recorded& t, std::size_t most) {
        bool any = false;
        // Waiting a millisecond on a quiet stream: no longer, with others to read.
        for (std::size_t k = 0; k < most && recording.more(); ++k) {
          auto entry = reading.tail.next(std::chrono::milliseconds{1});
          if (!entry) break;
          const auto sequence = entry->sequence.value_or(0);
          if (entry->sequence && reading.last && sequence > *reading.last + 1) reading.lost += sequence - *reading.last - 1;
          if (entry->sequence) reading.last = sequence;
          const auto data = std::as_bytes(std::span{entry->data.data(), entry->data.size()});
          recording.write(t, static_cast<std::uint32_t>(sequence), entry->stamp.value_or(Clock::now()), {data.begin(), data.end()});
          any = true;
        }
        recording.lost(t, reading.lost);
        return any;
      });
    }
  };
  open(sources);
  return recording.run([&] { open(inspector.sources()); }, [] {});
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
