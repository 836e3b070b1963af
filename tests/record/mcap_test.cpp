// MCAP files as Prime writes and reads them: round trips in every
// compression, files cut short or damaged, foreign files, a full disk.
#include <gtest/gtest.h>

#include <unistd.h>

#include <cstdint>
#include <cstring>
#include <filesystem>
#include <fstream>
#include <string>
#include <vector>

#include "prime/record/mcap_reader.hpp"
#include "prime/record/mcap_writer.hpp"

namespace {

namespace rec = prime::record;
using prime::Errc;
using prime::Failure;

// A file of this test's own, removed after it.
struct TempFile {
  TempFile() : path{std::filesystem::temp_directory_path() / ("prime-mcap-" + std::to_string(::getpid()) + "-" +
                                                              std::to_string(counter++) + ".mcap")} {}
  ~TempFile() { std::filesystem::remove(path); }
  std::filesystem::path path;
  static inline int counter = 0;
};

std::vector<std::byte> payload(std::uint64_t i, std::size_t size) {
  std::vector<std::byte> b(size);
  for (std::size_t k = 0; k < size; ++k) b[k] = std::byte(static_cast<unsigned char>((i * 31 + k) & 0xff));
  return b;
}

// Writes `n` messages alternating between two channels, each message's
// bytes a function of its index; log_time 1000 + i.
void write_file(const std::string& path, rec::Compression c, std::uint64_t n, std::size_t chunk_size = 4096) {
  rec::McapWriter w{path, {.compression = c, .chunk_size = chunk_size, .profile = ""}};
  const auto scan = w.add_schema("Scan", "prime", "struct Scan { u64 seq; }");
  const auto lidar = w.add_channel(scan, "sensors/lidar", "prime-raw", {{"qos", "block"}});
  const auto cam = w.add_channel(0, "sensors/cam", "prime-raw");
  for (std::uint64_t i = 0; i < n; ++i)
    w.write(i % 2 ? cam : lidar, static_cast<std::uint32_t>(i / 2), 1000 + i, 2000 + i, payload(i, 16 + i % 40));
  w.add_metadata("prime.losses", {{"sensors/lidar", "0"}, {"sensors/cam", "3"}});
  w.close();
}

std::vector<rec::Message> messages(const rec::McapReader& r) {
  std::vector<rec::Message> out;
  r.for_each_message([&](const rec::Message& m) { out.push_back(m); });
  return out;
}

Errc code_of(auto&& f) {
  try {
    f();
  } catch (const Failure& e) {
    return e.error().code;
  }
  ADD_FAILURE() << "no Failure thrown";
  return Errc::timeout;
}

class McapRoundTrip : public ::testing::TestWithParam<rec::Compression> {};

TEST_P(McapRoundTrip, WhatIsWrittenIsReadBackWithItsSummary) {
  TempFile f;
  constexpr std::uint64_t kN = 5000;
  write_file(f.path, GetParam(), kN);
  rec::McapReader r{f.path};
  ASSERT_TRUE(r.complete());
  const auto& s = r.summary();
  EXPECT_EQ(s.library, "prime");
  EXPECT_EQ(s.statistics.message_count, kN);
  EXPECT_EQ(s.statistics.channel_count, 2u);
  EXPECT_EQ(s.statistics.schema_count, 1u);
  EXPECT_EQ(s.statistics.message_start_time, 1000u);
  EXPECT_EQ(s.statistics.message_end_time, 1000 + kN - 1);
  EXPECT_GT(s.chunks.size(), 10u);  // 4 KiB chunks
  EXPECT_EQ(s.statistics.chunk_count, s.chunks.size());
  for (const auto& c : s.chunks) {
    EXPECT_EQ(c.compression, rec::compression_name(GetParam()));
    EXPECT_EQ(c.message_index_offsets.size(), 2u);
  }
  ASSERT_EQ(s.channels.size(), 2u);
  EXPECT_EQ(s.channels.at(1).topic, "sensors/lidar");
  EXPECT_EQ(s.channels.at(1).metadata.at("qos"), "block");
  EXPECT_EQ(s.schemas.at(1).name, "Scan");
  EXPECT_EQ(s.statistics.channel_message_counts.at(1), kN / 2);
  EXPECT_EQ(s.statistics.channel_message_counts.at(2), kN / 2);
  ASSERT_EQ(s.metadata.size(), 1u);
  EXPECT_EQ(s.metadata[0].values.at("sensors/cam"), "3");

  const auto all = messages(r);
  ASSERT_EQ(all.size(), kN);
  for (std::uint64_t i = 0; i < kN; ++i) {
    ASSERT_EQ(all[i].log_time, 1000 + i);
    ASSERT_EQ(all[i].publish_time, 2000 + i);
    ASSERT_EQ(all[i].channel_id, i % 2 ? 2 : 1);
    ASSERT_EQ(all[i].sequence, i / 2);
    ASSERT_EQ(all[i].data, payload(i, 16 + i % 40));
  }
}

INSTANTIATE_TEST_SUITE_P(Compressions, McapRoundTrip,
                         ::testing::Values(rec::Compression::none, rec::Compression::lz4, rec::Compression::zstd),
                         [](const auto& info) { return std::string{info.param == rec::Compression::none ? "none" : rec::compression_name(info.param)}; });

// A writer killed mid-file leaves no summary: the reader finds every
// complete chunk by scanning, and what a cut chunk held is lost.
TEST(Mcap, AFileCutShortIsReadUpToItsLastCompleteChunk) {
  TempFile f;
  write_file(f.path, rec::Compression::zstd, 5000);
  std::uint64_t cut_at = 0, kept = 0;
  {
    rec::McapReader r{f.path};
    const auto& chunks = r.summary().chunks;
    ASSERT_GT(chunks.size(), 4u);
    cut_at = chunks[3].offset + chunks[3].length / 2;  // in the middle of the fourth chunk
    // Log times rise with each message: the first three chunks hold those up to the third's end.
    r.for_each_message([&](const rec::Message& m) { kept += m.log_time <= chunks[2].message_end_time; });
  }
  std::filesystem::resize_file(f.path, cut_at);
  rec::McapReader r{f.path};
  EXPECT_FALSE(r.complete());
  EXPECT_EQ(r.summary().chunks.size(), 3u);
  EXPECT_EQ(r.summary().statistics.message_count, kept);
  EXPECT_EQ(messages(r).size(), kept);
  EXPECT_EQ(r.summary().channels.size(), 2u);
}

TEST(Mcap, ADamagedChunkFailsItsCheckByName) {
  TempFile f;
  write_file(f.path, rec::Compression::none, 2000);
  std::uint64_t at = 0;
  {
    rec::McapReader r{f.path};
    at = r.summary().chunks[1].offset + r.summary().chunks[1].length - 5;  // inside its records
  }
  {
    std::fstream io{f.path, std::ios::in | std::ios::out | std::ios::binary};
    io.seekg(static_cast<std::streamoff>(at));
    char c = 0;
    io.read(&c, 1);
    c = static_cast<char>(c ^ 0x5a);
    io.seekp(static_cast<std::streamoff>(at));
    io.write(&c, 1);
  }
  rec::McapReader r{f.path};
  try {
    r.for_each_message([](const rec::Message&) {});
    FAIL() << "a damaged chunk was read";
  } catch (const Failure& e) {
    EXPECT_EQ(e.error().code, Errc::damaged);
    EXPECT_NE(e.error().message.find("fail their CRC"), std::string::npos) << e.error().message;
  }
}

TEST(Mcap, ADamagedSummaryFailsItsCheck) {
  TempFile f;
  write_file(f.path, rec::Compression::lz4, 500);
  const auto size = std::filesystem::file_size(f.path);
  {
    std::fstream io{f.path, std::ios::in | std::ios::out | std::ios::binary};
    io.seekp(static_cast<std::streamoff>(size - 8 - 29 - 40));  // in the summary offsets, before the footer
    const char junk = 0x7f;
    io.write(&junk, 1);
  }
  EXPECT_EQ(code_of([&] { rec::McapReader r{f.path}; }), Errc::damaged);
}

TEST(Mcap, AForeignOrMissingFileIsRefusedByName) {
  TempFile f;
  std::ofstream{f.path} << "not a recording at all, just text\n";
  try {
    rec::McapReader r{f.path};
    FAIL();
  } catch (const Failure& e) {
    EXPECT_EQ(e.error().code, Errc::invalid_argument);
    EXPECT_NE(e.error().message.find("is not an MCAP file"), std::string::npos);
  }
  EXPECT_EQ(code_of([] { rec::McapReader r{"/nonexistent/dir/x.mcap"}; }), Errc::not_found);
  EXPECT_EQ(code_of([] { rec::McapWriter w{"/nonexistent/dir/x.mcap"}; }), Errc::not_found);
}

TEST(Mcap, AFullDiskIsNoSpace) {
  if (!std::filesystem::exists("/dev/full")) GTEST_SKIP() << "no /dev/full here";
  EXPECT_EQ(code_of([] { rec::McapWriter w{"/dev/full"}; }), Errc::no_space);
}

TEST(Mcap, UnknownChannelsAndClosedWritersAreRefused) {
  TempFile f;
  rec::McapWriter w{f.path};
  std::byte b{};
  EXPECT_EQ(code_of([&] { w.write(7, 0, 0, 0, {&b, 1}); }), Errc::invalid_argument);
  EXPECT_EQ(code_of([&] { w.add_channel(3, "x", "prime-raw"); }), Errc::invalid_argument);
  w.close();
  EXPECT_EQ(code_of([&] { w.add_channel(0, "x", "prime-raw"); }), Errc::invalid_argument);
}

}  // namespace
