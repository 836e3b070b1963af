#pragma once

// A small mutation fuzzer for Prime's boundaries, built with the project's
// own compiler (GCC: the clang that ships libFuzzer beside it in Debian
// cannot compile std::expected from GCC's library). Each target gives a
// valid seed and a function that takes one input; the driver feeds it the
// seed, then mutations of it (bits flipped, bytes and words set to values
// at the edges of their ranges, pieces copied, cut and repeated) for a
// bounded time, from a fixed random seed, so a run is repeatable. A crash
// or a sanitizer's report ends the run; so does an input that runs longer
// than its bound (a hang), and in both cases the input is written out.
//
//   target [--seconds S] [--seed N] [--input FILE]
//
// --input runs one saved input, as libFuzzer would.

#include <fcntl.h>
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#include <sanitizer/common_interface_defs.h>
#endif

#include <algorithm>
#include <chrono>
#include <csignal>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <cstring>
#include <fstream>
#include <functional>
#include <iterator>
#include <random>
#include <span>
#include <string>
#include <unistd.h>
#include <vector>

namespace prime::fuzz {

using Input = std::vector<std::uint8_t>;
using Target = std::function<void(std::span<const std::uint8_t>)>;

inline constexpr unsigned kSecondsPerInput = 10;

namespace detail {

inline const Input* current = nullptr;
inline char saved_path[64] = "fuzz-input.bin";

// Writes the input under way where the log says, with no allocation (it
// runs in a signal handler too).
inline void save_current() noexcept {
  if (!current) return;
  const int fd = ::open(saved_path, O_CREAT | O_TRUNC | O_WRONLY, 0644);
  if (fd < 0) return;
  (void)!::write(fd, current->data(), current->size());
  ::close(fd);
}

inline void on_alarm(int) {
  static const char text[] = "fuzz: an input ran longer than its bound (a hang); saved to ";
  (void)!::write(2, text, sizeof text - 1);
  (void)!::write(2, saved_path, std::strlen(saved_path));
  (void)!::write(2, "\n", 1);
  save_current();
  ::_exit(3);
}

inline void on_crash(int signal) {
  save_current();
  std::signal(signal, SIG_DFL);
  std::raise(signal);
}

inline std::uint64_t edge_value(std::mt19937_64& random) {
  static constexpr std::uint64_t kEdges[] = {0,           1,           2,           7,          8,
                                             63,          64,          127,         128,        255,
                                             4096,        0x7fffffff,  0x80000000,  0xffffffff, 1ull << 24,
                                             (1ull << 24) - 1, 1ull << 32, 1ull << 39, 1ull << 40, (1ull << 40) - 1,
                                             1ull << 62,  1ull << 63,   ~0ull >> 1,  ~0ull,      ~0ull - 1};
  if (random() % 4 == 0) return random() >> (random() % 64);
  return kEdges[random() % std::size(kEdges)];
}

}  // namespace detail

// `input` changed in one to four places.
inline void mutate(Input& input, std::mt19937_64& random, bool may_resize) {
  const int changes = 1 + static_cast<int>(random() % 4);
  for (int k = 0; k < changes; ++k) {
    if (input.empty()) {
      input.push_back(static_cast<std::uint8_t>(random()));
      continue;
    }
    const auto at = random() % input.size();
    switch (random() % (may_resize ? 7 : 4)) {
      case 0: input[at] ^= static_cast<std::uint8_t>(1u << (random() % 8)); break;
      case 1: input[at] = static_cast<std::uint8_t>(detail::edge_value(random)); break;
      case 2: {  // a word at an aligned place, as a count or an index would lie
        const auto word = at / 8 * 8;
        const auto value = detail::edge_value(random);
        const auto width = std::min<std::size_t>(random() % 2 ? 8 : 4, input.size() - word);
        std::memcpy(input.data() + word, &value, width);
        break;
      }
      case 3: {  // a piece copied elsewhere
        const auto from = random() % input.size();
        const auto n = std::min<std::size_t>({1 + random() % 16, input.size() - from, input.size() - at});
        std::memmove(input.data() + at, input.data() + from, n);
        break;
      }
      case 4: input.erase(input.begin() + static_cast<std::ptrdiff_t>(at), input.begin() + static_cast<std::ptrdiff_t>(std::min(input.size(), at + 1 + random() % 8))); break;
      case 5: input.insert(input.begin() + static_cast<std::ptrdiff_t>(at), 1 + random() % 8, static_cast<std::uint8_t>(random())); break;
      case 6: {  // a piece repeated, as nesting or a long run would be
        const auto n = std::min<std::size_t>(1 + random() % 4, input.size() - at);
        const Input piece(input.begin() + static_cast<std::ptrdiff_t>(at), input.begin() + static_cast<std::ptrdiff_t>(at + n));
        for (int r = 0, times = 1 + static_cast<int>(random() % 64); r < times && input.size() < (1u << 20); ++r)
          input.insert(input.begin() + static_cast<std::ptrdiff_t>(at), piece.begin(), piece.end());
        break;
      }
    }
  }
}

// Runs `target` on `seeds` and on mutations of them, as the command line
// says. `may_resize`: whether inputs may change length (a parser's text may;
// a segment's image keeps its size).
inline int run(int argc, char** argv, const std::vector<Input>& seeds, const Target& target, bool may_resize) {
  double seconds = 5;
  std::uint64_t seed = 1;
  std::string replay;
  for (int i = 1; i + 1 < argc; i += 2) {
    const std::string flag = argv[i];
    if (flag == "--seconds") seconds = std::strtod(argv[i + 1], nullptr);
    else if (flag == "--seed") seed = std::strtoull(argv[i + 1], nullptr, 10);
    else if (flag == "--input") replay = argv[i + 1];
  }
  std::snprintf(detail::saved_path, sizeof detail::saved_path, "fuzz-input-%d.bin", static_cast<int>(::getpid()));
  std::signal(SIGALRM, detail::on_alarm);
#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
  // The sanitizer's own handlers report a crash (with its stack); the
  // input is saved as it dies.
  __sanitizer_set_death_callback([] { detail::save_current(); });
#else
  for (const int s : {SIGSEGV, SIGBUS, SIGILL, SIGFPE, SIGABRT}) std::signal(s, detail::on_crash);
#endif
  auto one = [&](const Input& input) {
    detail::current = &input;
    ::alarm(kSecondsPerInput);
    target(input);
    ::alarm(0);
    detail::current = nullptr;
  };
  if (!replay.empty()) {
    std::ifstream file{replay, std::ios::binary};
    const Input input{std::istreambuf_iterator<char>{file}, {}};
    one(input);
    std::printf("fuzz: ran %s\n", replay.c_str());
    return 0;
  }
  std::mt19937_64 random{seed};
  std::uint64_t runs = 0;
  const auto start = std::chrono::steady_clock::now();
  const auto budget = std::chrono::duration<double>{seconds};
  for (const auto& s : seeds) {
    one(s);
    ++runs;
  }
  Input input;
  while (std::chrono::steady_clock::now() - start < budget) {
    if (runs % 16 == 0 || input.empty()) input = seeds[random() % seeds.size()];  // back to a seed now and then
    mutate(input, random, may_resize);
    one(input);
    ++runs;
  }
  std::printf("fuzz: %llu inputs in %.1f s (seed %llu), no crash, no hang\n", static_cast<unsigned long long>(runs),
              seconds, static_cast<unsigned long long>(seed));
  return 0;
}

}  // namespace prime::fuzz
