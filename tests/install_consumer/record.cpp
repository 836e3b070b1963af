// Links recordings from an installed Prime: writes a small MCAP file with
// prime::record and plays it into a Liberty chain with Replay.
#include <prime/liberty.hpp>
#include <prime/record/mcap_writer.hpp>
#include <prime/record/replay.hpp>

#include <unistd.h>

#include <chrono>
#include <cstdio>
#include <span>
#include <string>
#include <vector>

int main() {
  const std::string file = "prime-install-consumer-" + std::to_string(::getpid()) + ".mcap";
  {
    prime::record::McapWriter w{file};
    const auto schema = w.add_schema(prime::Fingerprint::of<int>().describe(), "prime", "i32");
    const auto channel = w.add_channel(schema, "numbers", "prime-raw");
    for (int i = 1; i <= 3; ++i) w.write(channel, 0, 1000 + i, 1000 + i, std::as_bytes(std::span{&i, 1}));
  }
  prime::liberty::Core core;
  prime::record::Replay replay{core, file};
  auto doubled = replay.source<int>("numbers") | core.chain([](int x) { return 2 * x; }, "double");
  auto reader = doubled.subscribe();
  replay.start();
  std::vector<int> out;
  while (out.size() < 3)
    if (auto v = reader.read_for(std::chrono::seconds{5})) out.push_back(v->value);
    else break;
  core.stop();
  std::remove(file.c_str());
  return out == std::vector<int>{2, 4, 6} ? 0 : 1;
}
