// A recording played into chains in one process on its own clock: the same
// sets and outputs on every run, with no timing in them.
#include <gtest/gtest.h>

#include <unistd.h>

#include <chrono>
#include <cstdint>
#include <filesystem>
#include <string>
#include <vector>

#include "prime/liberty.hpp"
#include "prime/record/mcap_writer.hpp"
#include "prime/record/replay.hpp"
#include "prime/topology.hpp"

namespace {

using namespace std::chrono_literals;
namespace rec = prime::record;
using prime::Clock;
using prime::Errc;
using prime::Failure;

struct Scan {
  std::int64_t n;
  double range;
};
struct Odom {
  std::int64_t n;
  double speed;
};

// A drive: lidar at 10 Hz, odometry at 33 Hz with jitter, stamps on the
// steady clock (the file's clock offset is 0).
struct Drive {
  Drive() {
    rec::McapWriter w{path, {.compression = rec::Compression::zstd, .chunk_size = 2048, .profile = ""}};
    w.add_metadata("prime.clock", {{"steady_to_unix_ns", "0"}});
    const auto scan = w.add_channel(w.add_schema(prime::Fingerprint::of<Scan>().describe(), "prime", ""), "lidar", "prime-raw");
    const auto odom = w.add_channel(w.add_schema(prime::Fingerprint::of<Odom>().describe(), "prime", ""), "odom", "prime-raw");
    const std::int64_t t0 = 1'000'000'000;
    for (std::int64_t i = 0; i < 100; ++i) {
      const Scan s{i, 0.5 * static_cast<double>(i)};
      w.write(scan, static_cast<std::uint32_t>(i), static_cast<std::uint64_t>(t0 + i * 100'000'000), 0, std::as_bytes(std::span{&s, 1}));
    }
    for (std::int64_t i = 0; i < 330; ++i) {
      const Odom o{i, static_cast<double>(i % 7)};
      const auto jitter = (i * 7919) % 3'000'000;  // up to 3 ms
      w.write(odom, static_cast<std::uint32_t>(i), static_cast<std::uint64_t>(t0 + i * 30'303'030 + jitter), 0,
              std::as_bytes(std::span{&o, 1}));
    }
    w.close();
  }
  ~Drive() { std::filesystem::remove(path); }
  const std::string path = (std::filesystem::temp_directory_path() / ("prime-drive-" + std::to_string(::getpid()) + ".mcap")).string();
};

// Reads `reader` until the replay is done and what it made is drained.
template <class T>
std::vector<prime::Sample<T>> all_of(prime::Reader<T>& reader, const rec::Replay& replay) {
  std::vector<prime::Sample<T>> out;
  const auto give_up = Clock::now() + 60s;
  while (Clock::now() < give_up) {
    if (auto s = reader.read_for(10ms)) {
      out.push_back(std::move(*s));
    } else if (replay.finished()) {
      while (auto more = reader.try_read()) out.push_back(std::move(*more));
      return out;
    }
  }
  ADD_FAILURE() << "the replay did not finish";
  return out;
}

// One run: lidar and odometry synchronised, each set made into (scan n, odom n).
std::vector<std::pair<std::int64_t, std::int64_t>> synced_run(const std::string& file) {
  prime::liberty::Core core;
  rec::Replay replay{core, file};
  auto sets = prime::sync(prime::approximate_time(), replay.source<Scan>("lidar"), replay.source<Odom>("odom"));
  auto reader = sets.subscribe();
  replay.start();
  std::vector<std::pair<std::int64_t, std::int64_t>> pairs;
  for (const auto& s : all_of(reader, replay)) {
    const auto& [scan, odom] = s.value;
    EXPECT_LE(s.value.skew(), 20ms);  // the nearest odometry: at most half its period away, plus jitter
    pairs.emplace_back(scan.n, odom.n);
  }
  core.stop();
  return pairs;
}

TEST(Replay, ASyncOnARecordingMakesTheSameSetsOnEveryRun) {
  const Drive drive;
  const auto first = synced_run(drive.path);
  ASSERT_GE(first.size(), 95u);  // one set per scan, but for the last few no later odometry decides
  for (std::size_t i = 1; i < first.size(); ++i) EXPECT_GT(first[i].first, first[i - 1].first);
  for (int run = 0; run < 5; ++run) EXPECT_EQ(synced_run(drive.path), first) << "run " << run;
}

TEST(Replay, AChainOnOneRecordedTopicSeesEverySampleInOrderWithItsStamp) {
  const Drive drive;
  prime::liberty::Core core;
  rec::Replay replay{core, drive.path};
  auto doubled = replay.source<Scan>("lidar") | core.chain([](const Scan& s) { return s.range * 2; });
  auto reader = doubled.subscribe();  // before it plays: it sees every output
  replay.start();
  const auto got = all_of(reader, replay);
  ASSERT_EQ(got.size(), 100u);
  for (std::size_t i = 0; i < got.size(); ++i) {
    EXPECT_EQ(got[i].value, static_cast<double>(i));
    EXPECT_EQ(got[i].stamp.time_since_epoch(), 1s + i * 100ms);  // the recorded stamp, on the steady clock
  }
  core.stop();
}

// replay() plays one topic at once: its own readers see all of it.
TEST(Replay, OneTopicPlayedAtOnceIsReadWhole) {
  const Drive drive;
  prime::liberty::Core core;
  auto reader = rec::replay<Odom>(core, drive.path, "odom").subscribe();
  for (std::int64_t i = 0; i < 330; ++i) {
    auto s = reader.read_for(10s);
    ASSERT_TRUE(s) << "sample " << i;
    EXPECT_EQ(s->value.n, i);
  }
  EXPECT_FALSE(reader.try_read()) << "nothing after the last";
}

TEST(Replay, ATopicOfAnotherTypeOrNoneIsRefusedByName) {
  const Drive drive;
  prime::liberty::Core core;
  rec::Replay replay{core, drive.path};
  try {
    (void)replay.source<Odom>("lidar");
    FAIL() << "a topic of Scan replayed as Odom";
  } catch (const Failure& f) {
    EXPECT_EQ(f.error().code, Errc::type_mismatch);
    EXPECT_NE(f.error().message.find("was recorded as"), std::string::npos) << f.error().message;
  }
  try {
    (void)replay.source<Scan>("camera");
    FAIL();
  } catch (const Failure& f) {
    EXPECT_EQ(f.error().code, Errc::not_found);
  }
  replay.start();
  try {
    (void)replay.source<Scan>("lidar");
    FAIL();
  } catch (const Failure& f) {
    EXPECT_EQ(f.error().code, Errc::invalid_argument);
  }
}

}  // namespace
