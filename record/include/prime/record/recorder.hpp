#pragma once

#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <exception>
#include <map>
#include <memory>
#include <mutex>
#include <span>
#include <string>
#include <thread>
#include <vector>

#include "prime/record/mcap.hpp"
#include "prime/record/mcap_writer.hpp"

namespace prime::record {

// What the reading side of a recording writes into: a Recorder (every
// sample, into one file or a series), or a SnapshotRecorder (the last
// seconds, into a file when asked). One thread.
class Sink {
 public:
  virtual ~Sink() = default;
  // A topic, written as a schema and a channel; its index for write().
  virtual std::size_t add_topic(const Schema& schema, const Channel& channel) = 0;
  virtual void add_metadata(const Metadata& metadata) = 0;
  // How many samples of `topic` were lost before they were read, so far.
  virtual void lost(std::size_t topic, std::uint64_t so_far) = 0;
  // A message of `topic`. Its bytes are taken over: a reader that copied
  // them into a vector of its own moves it in, and they are not copied
  // again.
  virtual void write(std::size_t topic, std::uint32_t sequence, std::uint64_t log_time, std::uint64_t publish_time,
                     std::vector<std::byte> data) = 0;
  // Nothing more to read for a while: a moment to hand over what is collected.
  virtual void flush() = 0;
  // Writes what there is to write, and closes. Once.
  virtual void close() = 0;
  // The files written so far, in order; and their bytes.
  [[nodiscard]] virtual std::vector<std::string> files() const = 0;
  [[nodiscard]] virtual std::uint64_t bytes_written() const = 0;
};

// "drive.mcap", 3: "drive_3.mcap", a file of a series.
[[nodiscard]] std::string numbered_path(const std::string& path, std::size_t n);

struct RecorderOptions {
  WriterOptions file;                 // each file's compression and chunk size
  std::uint64_t max_size = 0;         // bytes a file reaches before the next is begun (0: one file)
  std::uint64_t max_duration = 0;     // ns of log time a file spans before the next is begun (0: one file)
  std::size_t max_queued = 256 << 20;  // bytes of messages queued for the writer before write() waits
};

// The writing side of a recording: messages queued by the reading side
// (copied, so it can let go of what it read at once) and written on a
// thread of its own, so compressing a chunk, the disk, or closing one
// file and beginning the next never holds the reading up. Split by size
// or by duration, the files are `<stem>_0.mcap`, `<stem>_1.mcap`, ...:
// each complete on its own (every schema, channel and metadata, its own
// summary) and, read in turn, holding every message once. A file ends at
// the first chunk boundary past its limit.
//
// The writer's error (Errc::no_space on a full disk, say) is thrown by the
// next write() or close(); what was written before it stays readable.
// add_topic, add_metadata, lost, write, flush and close: one thread.
class Recorder final : public Sink {
 public:
  Recorder(std::string path, RecorderOptions options);
  Recorder(const Recorder&) = delete;
  Recorder& operator=(const Recorder&) = delete;
  ~Recorder() override;  // close(), its error lost

  // A topic, written as a schema and a channel into the file being written
  // and every file after it; its index for write().
  std::size_t add_topic(const Schema& schema, const Channel& channel) override;
  // Metadata written into every file from the next on, and this one if
  // nothing is written yet (the clock, say).
  void add_metadata(const Metadata& metadata) override;
  // How many samples of `topic` were lost before the reading side read
  // them, so far: each file's metadata `prime.losses` counts those lost
  // between its first message and its last.
  void lost(std::size_t topic, std::uint64_t so_far) override;
  // Queues a message (collected here, handed to the writer a batch at a
  // time); waits while `max_queued` bytes are queued.
  void write(std::size_t topic, std::uint32_t sequence, std::uint64_t log_time, std::uint64_t publish_time,
             std::vector<std::byte> data) override;
  // Hands what is collected to the writer now: for the reading side to
  // call when it has nothing more to read for a while.
  void flush() override;
  // Writes what is queued and closes the last file. Once.
  void close() override;

  // The files begun so far, in order.
  [[nodiscard]] std::vector<std::string> files() const override;
  // Bytes in the files closed so far; messages written; the most bytes
  // ever queued at once.
  [[nodiscard]] std::uint64_t bytes_written() const override;
  [[nodiscard]] std::uint64_t messages_written() const;
  [[nodiscard]] std::size_t most_queued() const;

 private:
  struct Item {
    bool is_loss;  // a loss count (`lost`), not a message
    std::size_t topic;
    std::uint64_t lost;
    std::uint32_t sequence;
    std::uint64_t log_time, publish_time;
    std::vector<std::byte> data;
  };
  void push(Item item);
  void run();
  bool write_item(Item& item);  // false: not a message
  void begin_file();
  void catch_up();  // the topics and metadata added since the file was begun, into it
  void end_file();

  const std::string path_;
  const RecorderOptions options_;
  // The reading side's batch, not yet handed over.
  std::vector<Item> batch_;
  std::size_t batch_bytes_ = 0;
  // Shared with the writer thread, under mutex_.
  mutable std::mutex mutex_;
  std::condition_variable changed_;
  std::vector<Item> queue_;
  std::size_t queued_ = 0, most_queued_ = 0;
  bool closing_ = false;
  std::exception_ptr error_;
  std::vector<std::string> files_;
  std::uint64_t bytes_done_ = 0, messages_ = 0;
  std::vector<std::pair<Schema, Channel>> topics_;
  std::vector<Metadata> metadata_;
  // The writer thread's own (and the constructor's, before it starts).
  std::unique_ptr<McapWriter> file_;
  std::map<std::string, std::uint16_t> schema_ids_;  // by type name, in this file
  std::vector<std::uint16_t> channel_ids_;           // by topic, in this file
  std::size_t metadata_written_ = 0;                 // of metadata_, into this file
  std::uint64_t file_first_log_ = 0, file_messages_ = 0;
  std::vector<std::uint64_t> lost_, lost_at_start_;
  std::thread writer_;
  bool closed_ = false;
};

}  // namespace prime::record
