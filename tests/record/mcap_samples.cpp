// Writes sample recordings for outside readers to check: one per
// compression, and one of described types in ROS 2's encoding (as `prime
// record` writes them), into the folder given, and prints
// FILE:MESSAGES:CHANNELS[:fields] for each (what reference_reader/check.mjs
// takes; "fields": decode every message and check its fields).
#include <array>
#include <cstdint>
#include <iostream>
#include <string>
#include <utility>
#include <vector>

#include "prime/common/bounded_string.hpp"
#include "prime/common/bounded_vector.hpp"
#include "prime/common/fingerprint.hpp"
#include "prime/common/schema.hpp"
#include "prime/record/cdr.hpp"
#include "prime/record/mcap_writer.hpp"
#include "prime/record/prime_metadata.hpp"
#include "record/described.hpp"

namespace samples {

using described::Point;
using described::Pose;

// Bounded strings and vectors, a byte before a record: encoded field by field.
struct Reading {
  std::uint8_t quality;
  Point at;
  prime::bounded_string<12> name;
  prime::bounded_vector<float, 4> values;
  bool ok;
};
PRIME_DESCRIBE(Reading, quality, at, name, values, ok)

// The fields of message `i` of each (check.mjs computes the same).
Pose pose(std::uint32_t i) { return {{1.0 * i, 2.0 * i, -1.0 * i}, {0.5 * i, 0, 0, 1}, i % 7}; }
Reading reading(std::uint32_t i) {
  Reading r{};
  r.quality = static_cast<std::uint8_t>(i % 200);
  r.at = {0.25 * i, 0, 3};
  r.name = "r" + std::to_string(i % 1000);
  for (std::uint32_t k = 0; k < i % 5; ++k) r.values.push_back(static_cast<float>(k + i));
  r.ok = i % 2 == 0;
  return r;
}

// A channel of T as `prime record` writes one: its ros2msg schema, CDR
// messages, the fingerprint and description in its metadata.
template <class T>
std::pair<std::uint16_t, prime::record::CdrCodec> channel_of(prime::record::McapWriter& w, const std::string& topic) {
  namespace rec = prime::record;
  const auto type = prime::Fingerprint::of<T>();
  auto codec = *rec::CdrCodec::of(prime::schema_of<T>(), sizeof(T));
  const auto name = rec::ros2_name(prime::read_text(type.name));
  auto metadata = rec::fingerprint_metadata(type);
  metadata[rec::kTypeEntry] = type.describe();
  metadata[rec::kDescriptionEntry] = prime::schema_of<T>();
  const auto schema = w.add_schema(name, "ros2msg", codec.definition(name));
  return {w.add_channel(schema, topic, "cdr", metadata), codec};
}

}  // namespace samples

int main(int argc, char** argv) {
  namespace rec = prime::record;
  if (argc != 2) {
    std::cerr << "usage: mcap_samples FOLDER\n";
    return 2;
  }
  constexpr std::uint64_t kMessages = 3000;
  for (const auto& [compression, name] : {std::pair{rec::Compression::none, "none"}, std::pair{rec::Compression::lz4, "lz4"},
                                          std::pair{rec::Compression::zstd, "zstd"}}) {
    const auto path = std::string{argv[1]} + "/" + name + ".mcap";
    rec::McapWriter w{path, {.compression = compression, .chunk_size = 4096, .profile = ""}};
    const auto scan = w.add_schema("Scan", "prime", "struct Scan { u64 seq; }");
    const auto lidar = w.add_channel(scan, "sensors/lidar", "prime-raw", {{"qos", "block"}});
    const auto cam = w.add_channel(0, "sensors/cam", "prime-raw");
    for (std::uint64_t i = 0; i < kMessages; ++i) {
      const std::vector<std::byte> data(16 + i % 40, std::byte(i & 0xff));
      w.write(i % 2 ? cam : lidar, static_cast<std::uint32_t>(i / 2), 1000 + i, 2000 + i, data);
    }
    w.add_metadata("prime.losses", {{"sensors/lidar", "0"}, {"sensors/cam", "0"}});
    w.close();
    std::cout << path << ':' << kMessages << ":2\n";
  }
  {
    const auto path = std::string{argv[1]} + "/described.mcap";
    rec::McapWriter w{path, {.compression = rec::Compression::zstd, .chunk_size = 4096, .profile = "ros2"}};
    const auto [poses, pose_codec] = samples::channel_of<samples::Pose>(w, "robot/pose");
    const auto [readings, reading_codec] = samples::channel_of<samples::Reading>(w, "robot/reading");
    std::vector<std::byte> cdr;
    for (std::uint32_t i = 0; i < kMessages; ++i) {
      if (i % 2 == 0) {
        const auto p = samples::pose(i);
        pose_codec.encode(std::as_bytes(std::span{&p, 1}), cdr);
        w.write(poses, i, 1000 + i, 2000 + i, cdr);
      } else {
        const auto r = samples::reading(i);
        reading_codec.encode(std::as_bytes(std::span{&r, 1}), cdr);
        w.write(readings, i, 1000 + i, 2000 + i, cdr);
      }
    }
    w.close();
    std::cout << path << ':' << kMessages << ":2:fields\n";
  }
}
