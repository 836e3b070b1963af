#pragma once

#include <cstddef>
#include <cstdint>
#include <deque>
#include <memory>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "prime/record/recorder.hpp"

namespace prime::record {

// A recording kept in memory, for the moment something goes wrong: the
// samples that arrived in the last `window` ns (at most `max_bytes` of
// them), each take() writing them into the next file of a series
// (`<stem>_0.mcap`, `<stem>_1.mcap`, ...) on a thread of its own while
// the reading goes on. Each file is complete on its own, with the losses
// that fell in its window. Errors are the Recorder's, thrown by take() or
// close(). One thread.
class SnapshotRecorder final : public Sink {
 public:
  SnapshotRecorder(std::string path, RecorderOptions options, std::uint64_t window, std::size_t max_bytes = std::size_t{1} << 30);
  ~SnapshotRecorder() override;  // close(), its error lost

  std::size_t add_topic(const Schema& schema, const Channel& channel) override;
  void add_metadata(const Metadata& metadata) override;
  void lost(std::size_t topic, std::uint64_t so_far) override;
  void write(std::size_t topic, std::uint32_t sequence, std::uint64_t log_time, std::uint64_t publish_time,
             std::vector<std::byte> data) override;
  void flush() override {}
  void close() override;
  [[nodiscard]] std::vector<std::string> files() const override { return files_; }
  [[nodiscard]] std::uint64_t bytes_written() const override;

  // Begins writing what it holds into the next file; returns its name and
  // how many messages go into it.
  std::pair<std::string, std::size_t> take();
  // The span of arrival times it holds now, in ns.
  [[nodiscard]] std::uint64_t held_span() const noexcept;

 private:
  struct Held {
    bool is_loss;
    std::size_t topic;
    std::uint64_t lost;  // so far, for a loss
    std::uint32_t sequence;
    std::uint64_t log_time, publish_time;
    std::vector<std::byte> data;
  };
  void trim();

  const std::string path_;
  const RecorderOptions options_;
  const std::uint64_t window_;
  const std::size_t max_bytes_;
  std::vector<std::pair<Schema, Channel>> topics_;
  std::vector<Metadata> metadata_;
  std::deque<Held> held_;
  std::size_t bytes_ = 0;
  std::uint64_t newest_ = 0;                 // arrival of the last sample
  std::vector<std::uint64_t> lost_at_start_;  // per topic: lost before the window held
  struct Writing {
    std::unique_ptr<Recorder> recorder;
    std::thread closing;  // closes it once all is written
    std::exception_ptr error;
  };
  std::vector<std::unique_ptr<Writing>> writing_;
  std::vector<std::string> files_;
  bool closed_ = false;
};

}  // namespace prime::record
