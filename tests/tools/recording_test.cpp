// prime record, record info, record recover and play against real
// processes: what is recorded is what was published, and what is played
// is what was recorded, at its timing, in its order, with its stamps.
#include <gtest/gtest.h>
#include <signal.h>

#include <chrono>
#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <optional>
#include <thread>
#include <string>
#include <vector>

#include "optimus/support/redis_server.hpp"
#include "prime/optimus.hpp"
#include "prime/optimus/inspect.hpp"
#include "prime/record/mcap_reader.hpp"
#include "prime/record/mcap_writer.hpp"
#include "prime/record/prime_metadata.hpp"
#include "prime/shm.hpp"
#include "shm/domain.hpp"
#include "shm/messages.hpp"
#include "shm/peer_process.hpp"
#include "support/within.hpp"
#include "tool_runs.hpp"

namespace prime::test {
namespace {

using namespace std::chrono_literals;

// A topic its reader never loses a sample of: the player waits for it.
constexpr shm::TopicQos kLossless{.capacity = 256, .overflow = Overflow::block, .block_timeout = 10s};

// A tick as recorded: its number, and its stamp as published.
struct Recorded {
  std::uint64_t n;
  Clock::time_point stamp;
  std::uint64_t log_time;
  friend bool operator==(const Recorded&, const Recorded&) = default;
};

// Message `m` of `file` as the tick it was: its channel's CDR decoded
// (a described type is recorded as ROS 2 says it).
Tick tick_of(const record::McapReader& reader, const record::Message& m, const std::string& file) {
  const auto codec = record::recorded_codec(reader.summary().channels.at(m.channel_id), sizeof(Tick), file);
  const auto bytes = codec ? codec->decode(m.data, file) : m.data;
  Tick tick;
  if (bytes.size() != sizeof tick) throw std::runtime_error{"not a tick"};
  std::memcpy(&tick, bytes.data(), sizeof tick);
  return tick;
}

// The ticks in `file`, in the order written.
std::vector<Recorded> ticks_in(const std::filesystem::path& file) {
  record::McapReader reader{file};
  const auto offset = record::steady_to_unix_ns(reader.summary(), file);
  std::vector<Recorded> out;
  reader.for_each_message([&](const record::Message& m) {
    const auto tick = tick_of(reader, m, file);
    out.push_back({tick.n, Clock::time_point{std::chrono::nanoseconds{static_cast<std::int64_t>(m.log_time) - offset}}, m.log_time});
  });
  return out;
}

// The next `n` ticks `reader` reads (fewer, when one is not there within 10 s).
template <class Reader>
std::vector<Recorded> ticks_read(Reader& reader, std::size_t n) {
  std::vector<Recorded> out;
  while (out.size() < n) {
    auto s = reader.read_for(10s);
    if (!s) break;
    out.push_back({s->value->n, s->stamp, 0});
  }
  return out;
}

// `prime play <args...>` into `domain`, while `reader` reads the `n`
// ticks it plays (a `block` topic's reader that stops reading is passed
// over after the publisher's block timeout: it reads as they come).
template <class Reader>
std::pair<Run, std::vector<Recorded>> play_and_read(const std::string& domain, std::vector<std::string> args, Reader& reader,
                                                    std::size_t n) {
  args.insert(args.begin(), {PRIME_TOOL_PATH, "--domain", domain, "play"});
  auto play = PeerProcess::command(std::move(args), true);
  auto read = ticks_read(reader, n);
  auto out = play.all_output();
  return {Run{play.exit_code().value_or(-1), out}, std::move(read)};
}

// `n` ticks of a 500 Hz publisher recorded into `file` (chunks of `chunk` bytes).
void record_ticks(const std::string& domain, const std::filesystem::path& file, std::size_t n, const std::string& chunk = "1048576") {
  const auto r = prime(domain, {"record", "tool/ticks", "-o", file, "-n", std::to_string(n), "--chunk-size", chunk});
  if (r.code != 0) throw std::runtime_error{"record failed: " + r.out};
}

// `n` ticks of a 500 Hz publisher in `domain` (started for them) recorded
// into `file`, as read back.
std::vector<Recorded> ticks_recorded(const std::string& domain, const std::filesystem::path& file, std::size_t n) {
  PeerProcess ticks{{"ticks", domain, "tool/ticks", "500", "0"}};
  if (!ticks.says("publishing")) throw std::runtime_error{"the ticks peer did not start"};
  record_ticks(domain, file, n);
  return ticks_in(file);
}

TEST(PrimeToolRecord, RecordsEveryTickOfAPublisherAndInfoCountsThem) {
  const auto domain = unique_domain("tool-record");
  PeerProcess ticks{{"ticks", domain, "tool/ticks", "500", "0"}};
  ASSERT_TRUE(ticks.says("publishing"));
  const auto file = std::filesystem::temp_directory_path() / (domain + ".mcap");
  const auto recorded = prime(domain, {"record", "tool/ticks", "-o", file, "-n", "300", "--compression", "lz4"});
  ASSERT_EQ(recorded.code, 0) << recorded.out;
  EXPECT_NE(recorded.out.find("recorded 300 samples of 'tool/ticks'"), std::string::npos) << recorded.out;

  record::McapReader reader{file};
  ASSERT_TRUE(reader.complete());
  const auto& summary = reader.summary();
  ASSERT_EQ(summary.channels.size(), 1u);
  const auto& channel = summary.channels.begin()->second;
  EXPECT_EQ(channel.topic, "tool/ticks");
  // A described type, as ROS 2 says it: tools that know ROS 2 decode it field by field.
  const auto& schema = summary.schemas.at(channel.schema_id);
  EXPECT_EQ(schema.name, "prime_test/msg/Tick");
  EXPECT_EQ(schema.encoding, "ros2msg");
  EXPECT_EQ(schema.data, "uint64 n\nfloat64 x\nstring<=8 tag\n");
  EXPECT_EQ(channel.message_encoding, "cdr");
  EXPECT_EQ(record::recorded_type(summary, channel), Fingerprint::of<test::Tick>().describe());
  EXPECT_EQ(record::recorded_fingerprint(summary, channel, file), Fingerprint::of<test::Tick>());  // to make its topic again
  EXPECT_EQ(summary.statistics.message_count, 300u);
  // Every sample is in the file or counted lost (overwritten before the
  // recorder read it: a drop_oldest topic on a loaded machine).
  std::optional<std::uint64_t> previous;
  std::uint64_t gaps = 0, last_time = 0;
  reader.for_each_message([&](const record::Message& m) {
    // CDR: the header, n, x, then tag as a length (with its NUL) and its characters.
    ASSERT_GE(m.data.size(), 4u + 8 + 8 + 4);
    EXPECT_EQ(m.data[0], std::byte{0});
    EXPECT_EQ(m.data[1], std::byte{1});
    const auto tick = tick_of(reader, m, file);
    EXPECT_EQ(tick.x, static_cast<double>(tick.n) / 2);
    EXPECT_EQ(tick.tag.view(), "t" + std::to_string(tick.n % 100));
    std::uint32_t tag_length;
    std::memcpy(&tag_length, m.data.data() + 4 + 16, 4);
    EXPECT_EQ(tag_length, tick.tag.view().size() + 1);
    if (previous) {
      ASSERT_GT(tick.n, *previous);
      gaps += tick.n - *previous - 1;
    }
    previous = tick.n;
    EXPECT_GT(m.log_time, last_time);
    EXPECT_GE(m.publish_time, m.log_time);  // arrival, after the stamp
    last_time = m.log_time;
  });
  ASSERT_EQ(summary.metadata.size(), 2u);  // the clock's offset, and the losses
  EXPECT_EQ(summary.metadata[1].name, "prime.losses");
  EXPECT_EQ(summary.metadata[1].values.at("tool/ticks"), std::to_string(gaps));
  const auto info = prime(domain, {"--json", "record", "info", file});
  ASSERT_EQ(info.code, 0) << info.out;
  const auto json = last_json(info.out);
  EXPECT_EQ(number(json, "messages"), 300);
  EXPECT_EQ(text(json, "compression"), "lz4");
  const auto& topic = json.object().at("topics").array().at(0);
  EXPECT_EQ(text(topic, "topic"), "tool/ticks");
  EXPECT_EQ(number(topic, "lost"), static_cast<double>(gaps));
  EXPECT_NEAR(number(topic, "rate"), 500, 100);
  std::filesystem::remove(file);
}

// A recorder kept from its CPU while its topic's ring is overwritten
// (stopped, here) records what the ring still holds, counts the rest as
// lost, and says why: how long the ring lasts, and a capacity that lasts.
TEST(PrimeToolRecord, ARecorderThatLosesSamplesSaysHowLongItsRingLasts) {
  const auto domain = unique_domain("tool-record-lost");
  shm::Core core{domain};
  auto publisher = core.publisher<Tick>("tool/short", {.capacity = 8});
  const auto file = std::filesystem::temp_directory_path() / (domain + ".mcap");
  auto recorder = PeerProcess::command({PRIME_TOOL_PATH, "--domain", domain, "record", "tool/short", "-o", file}, true);
  ASSERT_TRUE(recorder.line_starting("prime: recording 1 topic into " + file.string(), 10s));
  ::kill(recorder.pid(), SIGSTOP);
  for (std::uint64_t n = 0; n < 100; ++n) ASSERT_TRUE(publisher.publish(Tick{n, 0, {}}));
  ::kill(recorder.pid(), SIGCONT);
  ::kill(recorder.pid(), SIGINT);
  const auto out = recorder.all_output();
  ASSERT_EQ(recorder.exit_code(10s), 0) << out;
  EXPECT_NE(out.find("recorded 8 samples of 'tool/short', lost 92"), std::string::npos) << out;
  EXPECT_NE(out.find("'tool/short' lost samples its ring overwrote before they were read: it holds 8, "), std::string::npos) << out;
  EXPECT_NE(out.find("a topic capacity of "), std::string::npos) << out;
  const auto recorded = ticks_in(file);
  ASSERT_EQ(recorded.size(), 8u);
  for (std::size_t i = 0; i < recorded.size(); ++i) EXPECT_EQ(recorded[i].n, 92 + i) << "the newest eight, in order";
  std::filesystem::remove(file);
}

// A recorder killed with -9 leaves a file that is read and played up to
// its last complete chunk, says it was cut short, and is recovered whole.
TEST(PrimeToolRecord, ARecorderKilledMidFileLeavesAFileThatIsReadPlayedAndRecovered) {
  const auto domain = unique_domain("tool-record-kill");
  PeerProcess ticks{{"ticks", domain, "tool/ticks", "1000", "0"}};
  ASSERT_TRUE(ticks.says("publishing"));
  const auto file = std::filesystem::temp_directory_path() / (domain + ".mcap");
  auto recorder = PeerProcess::command(
      {PRIME_TOOL_PATH, "--domain", domain, "record", "--all", "-o", file, "--chunk-size", "1024"}, true);
  // Until a few chunks are in the file (each about 1 KiB of messages).
  ASSERT_TRUE(within(30s, [&] { return std::filesystem::exists(file) && std::filesystem::file_size(file) > 8 * 1024; }));
  recorder.kill9();
  record::McapReader reader{file};
  EXPECT_FALSE(reader.complete());
  EXPECT_GE(reader.summary().chunks.size(), 4u);
  std::uint64_t n = 0;
  std::optional<std::uint64_t> previous;
  reader.for_each_message([&](const record::Message& m) {
    const auto tick = tick_of(reader, m, file);
    if (previous) {
      EXPECT_GT(tick.n, *previous);  // in order, whole: nothing of a cut chunk is read
    }
    previous = tick.n;
    ++n;
  });
  EXPECT_EQ(n, reader.summary().statistics.message_count);
  EXPECT_GT(n, 50u);
  const auto info = prime(domain, {"record", "info", file});
  EXPECT_EQ(info.code, 0) << info.out;
  EXPECT_NE(info.out.find("cut short"), std::string::npos) << info.out;

  // Played: every complete chunk's samples.
  shm::Core core{domain};
  auto played = core.subscribe<Tick>("tool/played", {}, kLossless).subscribe();
  const auto [play, read] = play_and_read(domain, {file, "--rate", "max", "--remap", "tool/ticks:=tool/played"}, played, n);
  EXPECT_EQ(play.code, 0) << play.out;
  EXPECT_EQ(read.size(), n);

  // Recovered: the same messages, now with an index and a summary.
  const auto recovered = std::filesystem::temp_directory_path() / (domain + "-recovered.mcap");
  const auto recover = prime(domain, {"record", "recover", file, "-o", recovered});
  ASSERT_EQ(recover.code, 0) << recover.out;
  EXPECT_NE(recover.out.find("was cut short; " + std::to_string(n) + " messages"), std::string::npos) << recover.out;
  record::McapReader whole{recovered};
  EXPECT_TRUE(whole.complete());
  EXPECT_EQ(whole.summary().statistics.message_count, n);
  EXPECT_EQ(whole.summary().channels.size(), reader.summary().channels.size());
  EXPECT_EQ(ticks_in(recovered), ticks_in(file));
  const auto same = prime(domain, {"record", "recover", file, "-o", file});
  EXPECT_EQ(same.code, 2) << same.out;
  std::filesystem::remove(file);
  std::filesystem::remove(recovered);
}

TEST(PrimeToolRecord, BadFilesAndOptionsAreRefusedByName) {
  const auto domain = unique_domain("tool-record-bad");
  PeerProcess ticks{{"ticks", domain, "tool/ticks", "100", "0"}};
  ASSERT_TRUE(ticks.says("publishing"));
  const auto missing = prime(domain, {"record", "info", "/nonexistent/x.mcap"});
  EXPECT_EQ(missing.code, 3) << missing.out;
  const auto foreign_file = std::filesystem::temp_directory_path() / (domain + ".txt");
  { std::ofstream{foreign_file} << "hello\n"; }
  const auto foreign = prime(domain, {"record", "info", foreign_file});
  EXPECT_EQ(foreign.code, 2) << foreign.out;
  EXPECT_NE(foreign.out.find("is not an MCAP file"), std::string::npos) << foreign.out;
  std::filesystem::remove(foreign_file);
  const auto no_file = prime(domain, {"record", "tool/ticks"});
  EXPECT_EQ(no_file.code, 2) << no_file.out;
  EXPECT_NE(no_file.out.find("-o FILE.mcap"), std::string::npos) << no_file.out;
  const auto no_topic = prime(domain, {"record", "tool/nothing", "-o", "/tmp/never.mcap"});
  EXPECT_EQ(no_topic.code, 3) << no_topic.out;
  EXPECT_NE(no_topic.out.find("no topic 'tool/nothing'"), std::string::npos) << no_topic.out;

  const auto file = std::filesystem::temp_directory_path() / (domain + ".mcap");
  ASSERT_EQ(prime(domain, {"record", "tool/ticks", "-o", file, "-n", "20"}).code, 0);
  const auto play_missing = prime(domain, {"play", "/nonexistent/x.mcap"});
  EXPECT_EQ(play_missing.code, 3) << play_missing.out;
  const auto unknown_topic = prime(domain, {"play", file, "--topics", "tool/nothing"});
  EXPECT_EQ(unknown_topic.code, 3) << unknown_topic.out;
  EXPECT_NE(unknown_topic.out.find("no topic 'tool/nothing' in the recordings"), std::string::npos) << unknown_topic.out;
  const auto bad_remap = prime(domain, {"play", file, "--remap", "tool/ticks=tool/x"});
  EXPECT_EQ(bad_remap.code, 2) << bad_remap.out;
  EXPECT_NE(bad_remap.out.find("is not recorded:=published"), std::string::npos) << bad_remap.out;
  const auto bad_rate = prime(domain, {"play", file, "--rate", "0"});
  EXPECT_EQ(bad_rate.code, 2) << bad_rate.out;
  EXPECT_NE(bad_rate.out.find("--rate '0'"), std::string::npos) << bad_rate.out;
  const auto past_end = prime(domain, {"play", file, "--start", "3600"});
  EXPECT_EQ(past_end.code, 2) << past_end.out;
  EXPECT_NE(past_end.out.find("past the recordings' end"), std::string::npos) << past_end.out;
  // The recorder's topic, live and carrying its type, is another's to publish on.
  const auto taken = prime(domain, {"play", file});
  EXPECT_EQ(taken.code, 1) << taken.out;
  EXPECT_NE(taken.out.find("topic 'tool/ticks' already has a publisher"), std::string::npos) << taken.out;
  // A topic of another type is never published on.
  shm::Core core{domain};
  auto other = core.subscribe<Raw>("tool/raw");
  const auto mismatch = prime(domain, {"play", file, "--remap", "tool/ticks:=tool/raw"});
  EXPECT_EQ(mismatch.code, 1) << mismatch.out;
  EXPECT_NE(mismatch.out.find("topic 'tool/raw' carries"), std::string::npos) << mismatch.out;
  std::filesystem::remove(file);
}


// A full disk (a file size limit stands in for it) stops the recorder
// with the reason, and what it wrote before stays readable.
TEST(PrimeToolRecord, AFullDiskStopsTheRecorderByNameAndKeepsWhatItWrote) {
  const auto domain = unique_domain("tool-record-full");
  const auto file = std::filesystem::temp_directory_path() / (domain + ".mcap");
  PeerProcess ticks{{"ticks", domain, "tool/ticks", "2000", "0"}};
  ASSERT_TRUE(ticks.says("publishing"));
  const auto full = finished({"prlimit", "--fsize=65536", PRIME_TOOL_PATH, "--domain", domain, "record", "tool/ticks", "-o",
                              file.string(), "--chunk-size", "1024", "--duration", "60"});
  EXPECT_EQ(full.code, 1) << full.out;
  EXPECT_NE(full.out.find("writing failed after"), std::string::npos) << full.out;
  EXPECT_NE(full.out.find("stays readable"), std::string::npos) << full.out;
  const auto kept = ticks_in(file);
  EXPECT_GT(kept.size(), 200u);
  for (std::size_t i = 1; i < kept.size(); ++i) EXPECT_GT(kept[i].n, kept[i - 1].n);
  const auto info = prime(domain, {"record", "info", file});
  EXPECT_EQ(info.code, 0) << info.out;
  EXPECT_NE(info.out.find("cut short"), std::string::npos) << info.out;
  std::filesystem::remove(file);
}

// An Optimus source (--redis), recorded as the messages Optimus sent:
// readable back as its type, every one from the first on, none lost; play
// (which publishes into shared memory) refuses it by name.
TEST(PrimeToolRecord, RecordsAnOptimusSourceAsItsMessages) {
  RedisServer server;
  const auto domain = unique_domain("tool-record-optimus");
  const auto file = std::filesystem::temp_directory_path() / (domain + ".mcap");
  optimus::Core core{optimus::Options{.url = server.url(), .domain = domain}};
  auto ticks = core.publisher<int>("ticks");
  auto recorder = PeerProcess::command(
      {PRIME_TOOL_PATH, "--domain", domain, "--redis", server.url(), "record", "ticks", "-o", file.string(), "-n", "50"}, true);
  // Published at 500 Hz until the recorder has its 50 (it reads from when it joined).
  int published = 0;
  for (auto next = Clock::now(); published < 20000 && !recorder.exit_code(0ms); next += 2ms) {
    std::this_thread::sleep_until(next);
    ASSERT_TRUE(ticks.publish(published++));
  }
  const auto out = recorder.all_output();
  ASSERT_EQ(recorder.exit_code(10s), 0) << out;
  EXPECT_NE(out.find("recorded 50 samples of 'ticks', lost 0"), std::string::npos) << out;
  record::McapReader reader{file};
  ASSERT_TRUE(reader.complete());
  const auto& channel = reader.summary().channels.begin()->second;
  EXPECT_EQ(channel.message_encoding, "prime-optimus");
  EXPECT_EQ(record::recorded_type(reader.summary(), channel), Fingerprint::of<int>().describe());
  std::vector<int> values;
  reader.for_each_message([&](const record::Message& m) {
    const auto v = optimus::decode_message<int>(std::string_view{reinterpret_cast<const char*>(m.data.data()), m.data.size()}, "ticks");
    ASSERT_TRUE(v) << v.error().message;
    values.push_back(*v);
  });
  ASSERT_EQ(values.size(), 50u);
  for (std::size_t i = 1; i < values.size(); ++i) EXPECT_EQ(values[i], values[i - 1] + 1) << "every one, in order";
  const auto play = prime(unique_domain("tool-record-optimus-play"), {"play", file});
  EXPECT_EQ(play.code, 2) << play.out;
  EXPECT_NE(play.out.find("recorded from Optimus"), std::string::npos) << play.out;
  std::filesystem::remove(file);
}

// An Optimus recording played with --redis: onto a source registered with
// the recorded type, every message in order with its recorded stamp
// (--stamps keep), read by a typed reader; a shared-memory recording, or a
// message that is not one of the type's, is refused by name.
TEST(PrimeToolPlay, PlaysAnOptimusRecordingIntoOptimus) {
  RedisServer server;
  const auto domain = unique_domain("tool-play-optimus");
  const auto file = std::filesystem::temp_directory_path() / (domain + ".mcap");
  optimus::Core core{optimus::Options{.url = server.url(), .domain = domain}};
  {
    auto ticks = core.publisher<int>("ticks");
    auto recorder = PeerProcess::command(
        {PRIME_TOOL_PATH, "--domain", domain, "--redis", server.url(), "record", "ticks", "-o", file.string(), "-n", "40"}, true);
    ASSERT_TRUE(recorder.line_starting("prime: recording 1 topic", 10s));
    for (int n = 0; n < 40; ++n) ASSERT_TRUE(ticks.publish(1000 + n));
    const auto out = recorder.all_output();
    ASSERT_EQ(recorder.exit_code(10s), 0) << out;
  }
  // What was recorded: each value with its stamp as published.
  std::vector<std::pair<int, Clock::time_point>> recorded;
  {
    record::McapReader reader{file};
    const auto offset = record::steady_to_unix_ns(reader.summary(), file);
    reader.for_each_message([&](const record::Message& m) {
      const auto v = optimus::decode_message<int>(std::string_view{reinterpret_cast<const char*>(m.data.data()), m.data.size()}, "ticks");
      ASSERT_TRUE(v) << v.error().message;
      recorded.emplace_back(*v, Clock::time_point{std::chrono::nanoseconds{static_cast<std::int64_t>(m.log_time) - offset}});
    });
  }
  ASSERT_EQ(recorded.size(), 40u);

  auto reader = core.subscribe<int>("replayed", {.capacity = 100}).subscribe();
  const auto play = prime(domain, {"--redis", server.url(), "play", file, "--rate", "max", "--remap", "ticks:=replayed", "--stamps", "keep"});
  ASSERT_EQ(play.code, 0) << play.out;
  EXPECT_NE(play.out.find("played 40 samples on 'replayed'"), std::string::npos) << play.out;
  for (const auto& [value, stamp] : recorded) {
    auto s = reader.read_for(10s);
    ASSERT_TRUE(s) << "played value " << value;
    EXPECT_EQ(s->value, value);
    EXPECT_EQ(s->stamp, stamp) << "its stamp as recorded";
  }
  EXPECT_FALSE(reader.try_read()) << "nothing more";

  // A source of another type is refused by the registry, by name.
  auto other = core.publisher<double>("doubles");
  const auto clash = prime(domain, {"--redis", server.url(), "play", file, "--remap", "ticks:=doubles"});
  EXPECT_EQ(clash.code, 1) << clash.out;
  EXPECT_NE(clash.out.find("doubles"), std::string::npos) << clash.out;

  // A recording of shared-memory topics is for shared memory.
  const auto shm_file = std::filesystem::temp_directory_path() / (domain + "-shm.mcap");
  ticks_recorded(unique_domain("tool-play-optimus-shm"), shm_file, 5);
  const auto wrong_medium = prime(domain, {"--redis", server.url(), "play", shm_file});
  EXPECT_EQ(wrong_medium.code, 2) << wrong_medium.out;
  EXPECT_NE(wrong_medium.out.find("recorded from shared memory: play it without --redis"), std::string::npos) << wrong_medium.out;

  // A message that is not one of the recorded type's (a damaged or forged
  // file) is refused before it is appended.
  const auto forged = std::filesystem::temp_directory_path() / (domain + "-forged.mcap");
  {
    record::McapWriter w{forged, {.compression = record::Compression::none, .chunk_size = 1 << 20, .profile = ""}};
    // The type as the registry keeps it, from the source recorded.
    const auto sources = optimus::Inspector{optimus::Options{.url = server.url(), .domain = domain}}.sources();
    const auto ticks = std::ranges::find(sources, "ticks", &optimus::SourceSummary::name);
    ASSERT_NE(ticks, sources.end());
    EXPECT_TRUE(ticks->record.ends_with(" " + Fingerprint::of<int>().describe())) << ticks->record;
    const auto channel = w.add_channel(w.add_schema("int", "", ""), "ticks", "prime-optimus",
                                       {{record::kOptimusTypeEntry, ticks->record}, {record::kTypeEntry, Fingerprint::of<int>().describe()}});
    const std::string junk = "not a message";
    w.write(channel, 0, 1, 1, std::as_bytes(std::span{junk.data(), junk.size()}));
  }
  auto forged_reader = core.subscribe<int>("forged", {.capacity = 10}).subscribe();
  const auto refused = prime(domain, {"--redis", server.url(), "play", forged, "--remap", "ticks:=forged"});
  EXPECT_NE(refused.code, 0) << refused.out;
  EXPECT_NE(refused.out.find("source 'forged': not one of its messages"), std::string::npos) << refused.out;
  EXPECT_FALSE(forged_reader.read_for(100ms)) << "nothing appended";
  // A type record that is not the recorded type's never reaches the registry.
  const auto misnamed = std::filesystem::temp_directory_path() / (domain + "-misnamed.mcap");
  {
    record::McapWriter w{misnamed, {.compression = record::Compression::none, .chunk_size = 1 << 20, .profile = ""}};
    const auto channel = w.add_channel(w.add_schema("int", "", ""), "ticks", "prime-optimus",
                                       {{record::kOptimusTypeEntry, "0123456789abcdef float64"},
                                        {record::kTypeEntry, Fingerprint::of<int>().describe()}});
    const int one = 1;
    w.write(channel, 0, 1, 1, std::as_bytes(std::span{&one, 1}));
  }
  const auto misnamed_play = prime(domain, {"--redis", server.url(), "play", misnamed, "--remap", "ticks:=misnamed"});
  EXPECT_EQ(misnamed_play.code, 1) << misnamed_play.out;
  EXPECT_NE(misnamed_play.out.find("the Optimus type record of 'ticks' is \"0123456789abcdef float64\", not"), std::string::npos)
      << misnamed_play.out;
  const auto after = optimus::Inspector{optimus::Options{.url = server.url(), .domain = domain}}.sources();
  EXPECT_EQ(std::ranges::count(after, "misnamed", &optimus::SourceSummary::name), 0) << "nothing registered";
  for (const auto& f : {file, shm_file, forged, misnamed}) std::filesystem::remove(f);
}

// Split by size: a series of files that, played as one timeline, hold
// every sample recorded once, the losses counted in the file they fell in.
TEST(PrimeToolRecord, SplitFilesHoldEverySampleOnceAndPlayAsOne) {
  const auto domain = unique_domain("tool-record-split");
  const auto stem = std::filesystem::temp_directory_path() / domain;
  PeerProcess ticks{{"ticks", domain, "tool/ticks", "2000", "0"}};
  ASSERT_TRUE(ticks.says("publishing"));
  const auto recorded = prime(domain, {"record", "tool/ticks", "-o", stem.string() + ".mcap", "-n", "3000", "--chunk-size",
                                       "1024", "--max-size", "8192", "--compression", "lz4"});
  ASSERT_EQ(recorded.code, 0) << recorded.out;
  std::vector<std::string> files;
  for (int i = 0; std::filesystem::exists(stem.string() + "_" + std::to_string(i) + ".mcap"); ++i)
    files.push_back(stem.string() + "_" + std::to_string(i) + ".mcap");
  ASSERT_GE(files.size(), 4u) << recorded.out;
  EXPECT_NE(recorded.out.find(std::to_string(files.size()) + " files"), std::string::npos) << recorded.out;
  std::uint64_t gaps = 0, losses = 0;
  std::vector<Recorded> all;
  for (const auto& f : files) {
    const auto in = ticks_in(f);
    all.insert(all.end(), in.begin(), in.end());
    record::McapReader reader{f};
    for (const auto& m : reader.summary().metadata)
      if (m.name == record::kLossesMetadata) losses += std::stoull(m.values.at("tool/ticks"));
  }
  ASSERT_EQ(all.size(), 3000u);
  for (std::size_t i = 1; i < all.size(); ++i) {
    ASSERT_GT(all[i].n, all[i - 1].n) << "once each, in order, across every split";
    gaps += all[i].n - all[i - 1].n - 1;
  }
  EXPECT_EQ(losses, gaps);

  shm::Core core{domain};
  auto reader = core.subscribe<Tick>("tool/replayed", {}, kLossless).subscribe();
  std::vector<std::string> args{"--rate", "max", "--remap", "tool/ticks:=tool/replayed"};
  args.insert(args.end(), files.rbegin(), files.rend());
  const auto [played, read] = play_and_read(domain, args, reader, all.size());
  ASSERT_EQ(played.code, 0) << played.out;
  ASSERT_EQ(read.size(), all.size());
  for (std::size_t i = 0; i < read.size(); ++i) ASSERT_EQ(read[i].n, all[i].n) << i;
  for (const auto& f : files) std::filesystem::remove(f);
}

// --snapshot: only the last seconds in memory; each SIGUSR1 writes them
// into the next file of a series while the reading goes on.
TEST(PrimeToolRecord, ASnapshotHoldsTheLastSecondsAndIsWrittenOnASignal) {
  const auto domain = unique_domain("tool-record-snap");
  const auto stem = (std::filesystem::temp_directory_path() / domain).string();
  PeerProcess ticks{{"ticks", domain, "tool/ticks", "500", "0"}};
  ASSERT_TRUE(ticks.says("publishing"));
  shm::Core core{domain};
  auto published = [&] {
    for (const auto& t : core.registry().topics)
      if (t.name == "tool/ticks") return t.published;
    return std::uint64_t{0};
  };
  auto recorder = PeerProcess::command(
      {PRIME_TOOL_PATH, "--domain", domain, "record", "tool/ticks", "-o", stem + ".mcap", "--snapshot", "0.5"}, true);
  ASSERT_TRUE(recorder.line_starting("prime: keeping the last 0.5 s in memory", 10s));
  std::vector<std::vector<Recorded>> taken;
  for (int k = 0; k < 2; ++k) {
    const auto from = published();
    ASSERT_TRUE(within(30s, [&] { return published() >= from + 600; })) << "more than its window published";
    ::kill(recorder.pid(), SIGUSR1);
    const auto file = stem + "_" + std::to_string(k) + ".mcap";
    const auto said = recorder.line_starting("prime: " + file + ": the last ", 10s);
    ASSERT_TRUE(said);
    ASSERT_TRUE(within(10s, [&] {
      try {
        return record::McapReader{file}.complete();
      } catch (const Failure&) {
        return false;  // not yet whole
      }
    }));
    taken.push_back(ticks_in(file));
    const auto& t = taken.back();
    ASSERT_GE(t.size(), 150u) << *said;
    EXPECT_LE(t.size(), 300u) << "0.5 s at 500 Hz: " << *said;
    EXPECT_LE(t.back().stamp - t.front().stamp, 550ms);
    EXPECT_NE(said->find(std::to_string(t.size()) + " samples"), std::string::npos) << *said;
    for (std::size_t i = 1; i < t.size(); ++i) ASSERT_EQ(t[i].n, t[i - 1].n + 1) << "every sample of its window, in order";
    std::filesystem::remove(file);
  }
  EXPECT_GT(taken[1].front().n, taken[0].back().n) << "the second window is later";
  ::kill(recorder.pid(), SIGINT);
  EXPECT_EQ(recorder.exit_code(10s), 0);
  EXPECT_FALSE(std::filesystem::exists(stem + "_2.mcap"));
  EXPECT_FALSE(std::filesystem::exists(stem + ".mcap")) << "a snapshot recorder writes only when asked";
}

// Played at its timing, each sample with the stamp it was recorded with;
// at four times the speed, with stamps of when it is published.
TEST(PrimeToolPlay, PublishesARecordingAtItsTimingWithItsStamps) {
  const auto domain = unique_domain("tool-play");
  const auto file = std::filesystem::temp_directory_path() / (domain + ".mcap");
  const auto recorded = ticks_recorded(domain, file, 200);
  ASSERT_EQ(recorded.size(), 200u);
  const auto span = recorded.back().stamp - recorded.front().stamp;
  shm::Core core{domain};
  auto reader = core.subscribe<Tick>("tool/again", {}, kLossless).subscribe();

  auto started = Clock::now();
  auto play = PeerProcess::command(
      {PRIME_TOOL_PATH, "--domain", domain, "play", file, "--remap", "tool/ticks:=tool/again", "--stamps", "keep"}, true);
  auto read = ticks_read(reader, 200);
  ASSERT_EQ(play.exit_code(30s), 0) << play.all_output();
  EXPECT_GE(Clock::now() - started, span) << "at the recorded timing, never sooner";
  ASSERT_EQ(read.size(), 200u);
  for (std::size_t i = 0; i < read.size(); ++i) {
    EXPECT_EQ(read[i].n, recorded[i].n);
    EXPECT_EQ(read[i].stamp, recorded[i].stamp) << "--stamps keep: as recorded";
  }

  started = Clock::now();
  auto faster = PeerProcess::command(
      {PRIME_TOOL_PATH, "--domain", domain, "play", file, "--remap", "tool/ticks:=tool/again", "--rate", "4"}, true);
  read = ticks_read(reader, 200);
  ASSERT_EQ(faster.exit_code(30s), 0) << faster.all_output();
  const auto ended = Clock::now();
  EXPECT_GE(ended - started, span / 4);
  ASSERT_EQ(read.size(), 200u);
  for (std::size_t i = 0; i < read.size(); ++i) {
    EXPECT_EQ(read[i].n, recorded[i].n);
    EXPECT_GE(read[i].stamp, started) << "--stamps now (the default): when published";
    EXPECT_LE(read[i].stamp, ended);
  }
  std::filesystem::remove(file);
}

// Two files are one timeline, whatever order they are given in; a seek
// reads only the chunks from there on (a damaged chunk before it is
// never read, and is named when it is).
TEST(PrimeToolPlay, MergesFilesByTimeAndSeeksByTheIndex) {
  const auto domain = unique_domain("tool-play-merge");
  const auto dir = std::filesystem::temp_directory_path();
  const auto first = dir / (domain + "-1.mcap"), second = dir / (domain + "-2.mcap"), damaged = dir / (domain + "-x.mcap");
  {
    PeerProcess ticks{{"ticks", domain, "tool/ticks", "500", "0"}};
    ASSERT_TRUE(ticks.says("publishing"));
    record_ticks(domain, first, 100, "512");
    record_ticks(domain, second, 100, "512");
  }
  auto both = ticks_in(first);
  const auto later = ticks_in(second);
  ASSERT_LT(both.back().n, later.front().n);
  both.insert(both.end(), later.begin(), later.end());
  shm::Core core{domain};
  auto reader = core.subscribe<Tick>("tool/merged", {}, kLossless).subscribe();
  const auto [merged, read] = play_and_read(domain, {second, first, "--rate", "max", "--remap", "tool/ticks:=tool/merged"}, reader, 200);
  ASSERT_EQ(merged.code, 0) << merged.out;
  EXPECT_NE(merged.out.find("played 200 samples"), std::string::npos) << merged.out;
  ASSERT_EQ(read.size(), 200u);
  for (std::size_t i = 0; i < read.size(); ++i) EXPECT_EQ(read[i].n, both[i].n) << i;

  // The first chunk damaged: played from the start, it is named; from a
  // time past it, it is never read.
  std::filesystem::copy_file(first, damaged, std::filesystem::copy_options::overwrite_existing);
  record::McapReader index{first};
  const auto& chunks = index.summary().chunks;
  ASSERT_GE(chunks.size(), 3u);
  {
    std::fstream f{damaged, std::ios::in | std::ios::out | std::ios::binary};
    f.seekp(static_cast<std::streamoff>(chunks[0].offset + chunks[0].length - 4));
    f.put('\x5a').put('\x5a');
  }
  const auto whole = prime(domain, {"play", damaged, "--rate", "max", "--remap", "tool/ticks:=tool/merged"});
  EXPECT_EQ(whole.code, 1) << whole.out;
  EXPECT_NE(whole.out.find("the chunk at offset " + std::to_string(chunks[0].offset)), std::string::npos) << whole.out;
  while (reader.try_read()) {
  }
  const auto start = index.summary().statistics.message_start_time;
  const auto from = (chunks[0].message_end_time + chunks[1].message_start_time) / 2;
  char seconds[32];
  std::snprintf(seconds, sizeof seconds, "%.9f", static_cast<double>(from - start) / 1e9);
  const auto recorded = ticks_in(first);
  const auto skipped = static_cast<std::size_t>(std::ranges::count_if(recorded, [&](const Recorded& r) { return r.log_time < from; }));
  ASSERT_GT(skipped, 0u);
  const auto [seek, after] = play_and_read(domain, {damaged, "--start", seconds, "--rate", "max", "--remap", "tool/ticks:=tool/merged"},
                                           reader, recorded.size() - skipped);
  ASSERT_EQ(seek.code, 0) << seek.out;
  ASSERT_EQ(after.size(), recorded.size() - skipped);
  EXPECT_EQ(after.front().n, recorded[skipped].n);
  EXPECT_EQ(after.back().n, recorded.back().n);
  EXPECT_FALSE(reader.try_read()) << "nothing more";
  for (const auto& f : {first, second, damaged}) std::filesystem::remove(f);
}

// Into a domain no one has set up: the player makes it, and the topic,
// for the recorded type, so a reader of that type opens it; --loop plays
// on until Ctrl-C, which ends it as asked (exit 0).
TEST(PrimeToolPlay, MakesTheRecordedTopicForItsTypeAndLoopsUntilCtrlC) {
  const auto recorded_in = unique_domain("tool-play-rec");
  const auto file = std::filesystem::temp_directory_path() / (recorded_in + ".mcap");
  const auto recorded = ticks_recorded(recorded_in, file, 50);
  const auto domain = unique_domain("tool-play-new");
  ASSERT_FALSE(shm::access_of(domain));
  auto play = PeerProcess::command({PRIME_TOOL_PATH, "--domain", domain, "play", file, "--loop", "--rate", "4"}, true);
  ASSERT_TRUE(within(10s, [&] {
    const auto s = shm::inspect(domain);
    return s && std::ranges::any_of(s->topics, [](const auto& t) { return t.name == "tool/ticks"; });
  }));
  shm::Core core{domain};
  auto reader = core.subscribe<Tick>("tool/ticks").subscribe();  // the type recorded: no mismatch
  const auto read = ticks_read(reader, 3 * recorded.size());
  ASSERT_EQ(read.size(), 3 * recorded.size());
  std::size_t restarts = 0;
  for (std::size_t i = 1; i < read.size(); ++i) {
    if (read[i].n < read[i - 1].n) {
      ++restarts;
      EXPECT_EQ(read[i].n, recorded.front().n) << "again from the start";
    }
  }
  EXPECT_GE(restarts, 2u);
  ::kill(play.pid(), SIGINT);
  EXPECT_EQ(play.exit_code(10s), 0);
  EXPECT_NE(play.all_output().find("samples on 'tool/ticks'"), std::string::npos);
  std::filesystem::remove(file);
}

}  // namespace
}  // namespace prime::test
