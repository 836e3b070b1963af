// Writes sample recordings for outside readers to check: one per
// compression, into the folder given, and prints FILE:MESSAGES:CHANNELS for
// each (what reference_reader/check.mjs takes).
#include <cstdint>
#include <iostream>
#include <string>
#include <utility>
#include <vector>

#include "prime/record/mcap_writer.hpp"

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
}
