// A recording's writing side: one file, or a series split by size or by
// duration in which every message is written once, each file complete on
// its own with every topic, its metadata and its share of the losses.
#include <gtest/gtest.h>

#include <signal.h>
#include <sys/resource.h>
#include <unistd.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <map>
#include <optional>
#include <string>
#include <vector>

#include "prime/record/mcap_reader.hpp"
#include "prime/record/prime_metadata.hpp"
#include "prime/record/recorder.hpp"
#include "prime/record/snapshot_recorder.hpp"

namespace {

namespace rec = prime::record;

// A folder of this test's own, removed after it.
struct TempDir {
  TempDir()
      : path{std::filesystem::temp_directory_path() / ("prime-recorder-" + std::to_string(::getpid()) + "-" + std::to_string(counter++))} {
    std::filesystem::create_directories(path);
  }
  ~TempDir() { std::filesystem::remove_all(path); }
  std::filesystem::path path;
  static inline int counter = 0;
};

std::vector<std::byte> bytes_of(std::uint64_t i) {
  std::vector<std::byte> b(24);
  std::memcpy(b.data(), &i, sizeof i);
  return b;
}

std::size_t add(rec::Sink& r, const std::string& topic) {
  return r.add_topic({0, "Thing (24 bytes, align 8, layout 1)", "prime", "Thing: n u64"}, {0, 0, topic, "prime-raw", {{"k", "v"}}});
}

// Every message of `files` read in turn: (topic, the number in its bytes, log time).
struct Read {
  std::string topic;
  std::uint64_t n;
  std::uint64_t log_time;
};
std::vector<Read> read_all(const std::vector<std::string>& files) {
  std::vector<Read> out;
  for (const auto& f : files) {
    rec::McapReader reader{f};
    EXPECT_TRUE(reader.complete()) << f;
    reader.for_each_message([&](const rec::Message& m) {
      std::uint64_t n;
      std::memcpy(&n, m.data.data(), sizeof n);
      out.push_back({reader.summary().channels.at(m.channel_id).topic, n, m.log_time});
    });
  }
  return out;
}

std::map<std::string, std::string> metadata_named(const rec::Summary& s, const std::string& name) {
  for (const auto& m : s.metadata)
    if (m.name == name) return m.values;
  return {};
}

TEST(Recorder, SplitBySizeEveryMessageIsInExactlyOneFileAndEachFileIsWhole) {
  TempDir dir;
  constexpr std::uint64_t kMaxSize = 16 * 1024;
  constexpr std::uint64_t kMessages = 20000;
  rec::Recorder recorder{(dir.path / "drive.mcap").string(),
                         {.file = {.compression = rec::Compression::lz4, .chunk_size = 2048, .profile = ""},
                          .max_size = kMaxSize,
                          .max_queued = 4096}};  // a small queue: the writer is waited for, often
  recorder.add_metadata({rec::kClockMetadata, {{"steady_to_unix_ns", "12345"}}});
  const auto a = add(recorder, "a");
  const auto b = add(recorder, "b");
  std::uint64_t lost_a = 0;
  for (std::uint64_t i = 0; i < kMessages; ++i) {
    recorder.write(i % 2 == 0 ? a : b, static_cast<std::uint32_t>(i), 1'000'000 + i, 2'000'000 + i, bytes_of(i));
    if (i % 1000 == 999) recorder.lost(a, lost_a += 3);
  }
  recorder.close();
  const auto files = recorder.files();
  ASSERT_GE(files.size(), 5u);
  EXPECT_EQ(files[0], (dir.path / "drive_0.mcap").string());
  EXPECT_EQ(files[1], (dir.path / "drive_1.mcap").string());
  EXPECT_EQ(recorder.messages_written(), kMessages);
  EXPECT_LE(recorder.most_queued(), 4096u);

  const auto all = read_all(files);
  ASSERT_EQ(all.size(), kMessages);
  for (std::uint64_t i = 0; i < kMessages; ++i) {
    ASSERT_EQ(all[i].n, i) << "once each, in order, across the split";
    EXPECT_EQ(all[i].topic, i % 2 == 0 ? "a" : "b");
    EXPECT_EQ(all[i].log_time, 1'000'000 + i);
  }
  std::uint64_t losses = 0, bytes = 0;
  for (const auto& f : files) {
    rec::McapReader reader{f};
    const auto& s = reader.summary();
    EXPECT_EQ(s.channels.size(), 2u) << f << ": every topic, in every file";
    EXPECT_EQ(s.schemas.size(), 1u) << f;
    EXPECT_EQ(s.channels.begin()->second.metadata.at("k"), "v");
    EXPECT_EQ(metadata_named(s, rec::kClockMetadata).at("steady_to_unix_ns"), "12345") << f;
    losses += std::stoull(metadata_named(s, rec::kLossesMetadata).at("a"));
    EXPECT_EQ(metadata_named(s, rec::kLossesMetadata).at("b"), "0");
    // A file ends at the first chunk past its limit: one chunk (2 KiB of
    // records, less compressed) and the summary beyond it at most.
    EXPECT_LE(s.file_size, kMaxSize + 2048 + 4096) << f;
    bytes += s.file_size;
  }
  EXPECT_EQ(losses, lost_a) << "each loss counted in one file";
  EXPECT_EQ(recorder.bytes_written(), bytes);
}

TEST(Recorder, SplitByDurationEachFileSpansAtMostItsDuration) {
  TempDir dir;
  constexpr std::uint64_t kSecond = 1'000'000'000;
  rec::Recorder recorder{(dir.path / "drive").string(), {.file = {}, .max_duration = kSecond}};
  const auto a = add(recorder, "a");
  for (std::uint64_t i = 0; i < 1000; ++i) recorder.write(a, 0, i * 10'000'000, 0, bytes_of(i));  // 10 s, every 10 ms
  recorder.close();
  const auto files = recorder.files();
  ASSERT_EQ(files.size(), 10u);
  EXPECT_EQ(files[3], (dir.path / "drive_3").string());
  std::uint64_t n = 0;
  for (const auto& f : files) {
    rec::McapReader reader{f};
    const auto& st = reader.summary().statistics;
    EXPECT_LT(st.message_end_time - st.message_start_time, kSecond) << f;
    EXPECT_EQ(st.message_start_time, n * kSecond) << f;
    ++n;
  }
  EXPECT_EQ(read_all(files).size(), 1000u);
}

TEST(Recorder, ATopicAddedLaterIsInEveryFileFromItsFirstMessageOn) {
  TempDir dir;
  rec::Recorder recorder{(dir.path / "late.mcap").string(), {.file = {.compression = rec::Compression::none, .chunk_size = 256, .profile = ""}, .max_size = 2048}};
  const auto a = add(recorder, "a");
  for (std::uint64_t i = 0; i < 200; ++i) recorder.write(a, 0, i, i, bytes_of(i));
  const auto b = add(recorder, "b");
  for (std::uint64_t i = 200; i < 400; ++i) recorder.write(i % 2 ? a : b, 0, i, i, bytes_of(i));
  recorder.close();
  const auto files = recorder.files();
  ASSERT_GE(files.size(), 3u);
  // From the file its first message is in on, every file has it (the
  // writer may add it to an earlier one, having caught up meanwhile).
  bool seen = false;
  for (const auto& f : files) {
    rec::McapReader reader{f};
    reader.for_each_message([&](const rec::Message& m) { seen = seen || reader.summary().channels.at(m.channel_id).topic == "b"; });
    if (seen) {
      EXPECT_EQ(reader.summary().channels.size(), 2u) << f;
    }
  }
  EXPECT_TRUE(seen);
  const auto all = read_all(files);
  ASSERT_EQ(all.size(), 400u);
  for (std::uint64_t i = 200; i < 400; ++i) EXPECT_EQ(all[i].topic, i % 2 ? "a" : "b");
}

// A file size limit (RLIMIT_FSIZE) stands in for a full disk: a write past
// it fails (EFBIG, SIGXFSZ ignored) as one past a full disk does (ENOSPC).
struct FileSizeLimit {
  explicit FileSizeLimit(rlim_t bytes) {
    ::getrlimit(RLIMIT_FSIZE, &before);
    const rlimit limit{bytes, before.rlim_max};
    ::setrlimit(RLIMIT_FSIZE, &limit);
    ::signal(SIGXFSZ, SIG_IGN);
  }
  ~FileSizeLimit() {
    ::setrlimit(RLIMIT_FSIZE, &before);
    ::signal(SIGXFSZ, SIG_DFL);
  }
  rlimit before{};
};

TEST(Recorder, AFullDiskIsNoSpaceAndWhatWasWrittenStaysReadable) {
  TempDir dir;
  const auto path = (dir.path / "full.mcap").string();
  std::optional<prime::Error> error;
  {
    FileSizeLimit full{64 * 1024};
    try {
      rec::Recorder recorder{path, {.file = {.compression = rec::Compression::none, .chunk_size = 4096, .profile = ""}}};
      const auto a = add(recorder, "a");
      for (std::uint64_t i = 0; i < 100'000; ++i) recorder.write(a, 0, i, i, bytes_of(i));  // 2.4 MB
      recorder.close();
    } catch (const prime::Failure& f) {
      error = f.error();
    }
  }
  ASSERT_TRUE(error) << "2.4 MB written into room for 64 KiB";
  EXPECT_EQ(error->code, prime::Errc::no_space);
  EXPECT_NE(error->message.find(path), std::string::npos) << error->message;
  EXPECT_NE(error->message.find("stays readable"), std::string::npos) << error->message;
  rec::McapReader reader{path};
  EXPECT_FALSE(reader.complete());
  std::uint64_t n = 0;
  reader.for_each_message([&](const rec::Message& m) {
    std::uint64_t v;
    std::memcpy(&v, m.data.data(), sizeof v);
    EXPECT_EQ(v, n++) << "whole, in order, up to the last complete chunk";
  });
  EXPECT_GT(n, 500u) << "about 64 KiB of 55-byte records";
}

TEST(SnapshotRecorder, EachTakeWritesTheLastWindowWithTheLossesThatFellInIt) {
  TempDir dir;
  constexpr std::uint64_t kMs = 1'000'000;
  rec::SnapshotRecorder snapshots{(dir.path / "crash.mcap").string(), {}, 1000 * kMs};
  snapshots.add_metadata({rec::kClockMetadata, {{"steady_to_unix_ns", "7"}}});
  const auto a = add(snapshots, "a");
  std::uint64_t lost = 0;
  for (std::uint64_t i = 0; i < 5000; ++i) {  // 5 s, one a millisecond
    snapshots.write(a, static_cast<std::uint32_t>(i), i * kMs, i * kMs, bytes_of(i));
    if (i % 1000 == 500) snapshots.lost(a, lost += 10);  // at 0.5, 1.5, 2.5, 3.5 and 4.5 s
  }
  EXPECT_EQ(snapshots.held_span(), 1000 * kMs);
  const auto [first, messages] = snapshots.take();
  EXPECT_EQ(first, (dir.path / "crash_0.mcap").string());
  EXPECT_EQ(messages, 1001u) << "from 3.999 s to 4.999 s";
  for (std::uint64_t i = 5000; i < 5100; ++i) snapshots.write(a, 0, i * kMs, i * kMs, bytes_of(i));
  const auto [second, more] = snapshots.take();
  snapshots.close();
  const auto all = read_all({first});
  ASSERT_EQ(all.size(), 1001u);
  EXPECT_EQ(all.front().n, 3999u);
  EXPECT_EQ(all.back().n, 4999u);
  rec::McapReader reader{first};
  EXPECT_EQ(metadata_named(reader.summary(), rec::kLossesMetadata).at("a"), "10") << "only the loss at 4.5 s";
  EXPECT_EQ(metadata_named(reader.summary(), rec::kClockMetadata).at("steady_to_unix_ns"), "7");
  const auto later = read_all({second});
  ASSERT_EQ(later.size(), more);
  EXPECT_EQ(later.back().n, 5099u);
  EXPECT_EQ(snapshots.files().size(), 2u);
}

TEST(SnapshotRecorder, AMemoryBoundShortensTheWindow) {
  TempDir dir;
  rec::SnapshotRecorder snapshots{(dir.path / "bounded.mcap").string(), {}, 10'000'000'000, 24 * 100};
  const auto a = add(snapshots, "a");
  for (std::uint64_t i = 0; i < 1000; ++i) snapshots.write(a, 0, i, i, bytes_of(i));  // 24 bytes each
  const auto [file, messages] = snapshots.take();
  snapshots.close();
  EXPECT_EQ(messages, 100u) << "the newest that fit in 2400 bytes";
  EXPECT_EQ(read_all({file}).front().n, 900u);
}

TEST(Recorder, AFileThatCannotBeMadeIsTheConstructorsErrorAndAClosedOneRefusesMore) {
  try {
    rec::Recorder r{"/nonexistent/folder/x.mcap", {}};
    FAIL() << "made";
  } catch (const prime::Failure& f) {
    EXPECT_EQ(f.error().code, prime::Errc::not_found);
    EXPECT_NE(f.error().message.find("/nonexistent/folder/x.mcap"), std::string::npos);
  }
  TempDir dir;
  rec::Recorder r{(dir.path / "x.mcap").string(), {}};
  const auto a = add(r, "a");
  r.close();
  try {
    r.write(a, 0, 0, 0, bytes_of(0));
    FAIL() << "written after close";
  } catch (const prime::Failure& f) {
    EXPECT_EQ(f.error().code, prime::Errc::invalid_argument);
  }
}

}  // namespace
