#pragma once

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <mutex>
#include <optional>
#include <span>
#include <stop_token>
#include <string>
#include <vector>

#include "prime/logic/sample.hpp"

namespace prime::record {
class McapReader;
}

namespace prime::record::detail {

// A recording's samples released in the order of their stamps (the log
// times), on a clock of their own: a sample is released once every reader
// of its topic has come back for the next after the one before it in that
// order. A chain then sees the recorded interleaving of its sources, the
// same on every run, and never a value sooner than it can take it.
//
// Thread-safe.
class Timeline {
 public:
  explicit Timeline(std::string path);
  ~Timeline();

  // Adds topic `topic`, recorded as `type` (a Fingerprint's describe()),
  // before start(); returns its place. Throws Failure: Errc::not_found (no
  // such topic in the file), type_mismatch (recorded as another type),
  // invalid_argument (after start()).
  std::size_t add(const std::string& topic, const std::string& type, std::size_t size);
  // A reader of topic `slot`: from the sample the topic is at now.
  std::size_t join(std::size_t slot);
  void leave(std::size_t reader);

  // Releases from now on.
  void start();
  // Whether every sample has been taken and its readers have come back.
  [[nodiscard]] bool finished();
  [[nodiscard]] const std::string& path() const noexcept { return path_; }
  // What it waits for now, in words: the sample due and its readers.
  [[nodiscard]] std::string waiting_for();

  // The reader's next sample, waiting for its release until `deadline`
  // (none: nullopt) or a stop (Errc::stopped is thrown as Failure). The
  // bytes stay valid while the Timeline lives.
  struct Released {
    std::span<const std::byte> bytes;
    Clock::time_point stamp;
  };
  std::optional<Released> next(std::size_t reader, Clock::time_point deadline, const std::stop_token& stop);

 private:
  struct Topic {
    std::string name;
    std::vector<std::vector<std::byte>> samples;
    std::vector<Clock::time_point> stamps;
    std::vector<std::size_t> readers;
  };
  struct Reader {
    std::size_t slot;
    std::size_t taken = 0;     // samples of its topic it has been given
    std::size_t finished = 0;  // of those, the ones it came back after
    bool active = true;
  };
  struct Entry {
    Clock::time_point stamp;
    std::size_t slot;
    std::size_t index;
  };
  void advance();  // past every entry whose readers are done with it

  std::string path_;
  std::unique_ptr<McapReader> reader_;  // opened once; each topic added reads its messages through it
  std::int64_t steady_to_unix_ = 0;
  std::mutex mutex_;
  std::condition_variable moved_;
  std::deque<Topic> topics_;    // deques: a reader waiting holds references into them while others join
  std::deque<Reader> readers_;
  std::vector<Entry> order_;
  std::size_t at_ = 0;  // the entry released now
  bool started_ = false;
};

}  // namespace prime::record::detail
