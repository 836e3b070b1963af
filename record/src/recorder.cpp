// A recording's writing side: a queue, and a thread that writes it into
// one file or a series split by size or duration.
#include "prime/record/recorder.hpp"

#include <sys/resource.h>
#include <unistd.h>

#include <algorithm>
#include <iterator>

#include "prime/record/prime_metadata.hpp"
#include "prime/topology/detail/quiet_threads.hpp"

namespace prime::record {

std::string numbered_path(const std::string& path, std::size_t n) {
  const auto dot = path.rfind('.');
  const auto slash = path.rfind('/');
  const bool has_extension = dot != std::string::npos && (slash == std::string::npos || dot > slash);
  const auto stem = has_extension ? path.substr(0, dot) : path;
  return stem + "_" + std::to_string(n) + (has_extension ? path.substr(dot) : std::string{});
}

Recorder::Recorder(std::string path, RecorderOptions options) : path_{std::move(path)}, options_{std::move(options)} {
  begin_file();  // here, so that a file that cannot be made is this constructor's error
  writer_ = prime::detail::with_signals_blocked([this] { return std::thread{[this] { run(); }}; });
}

Recorder::~Recorder() {
  try {
    close();
  } catch (const Failure&) {
  }
}

std::size_t Recorder::add_topic(const Schema& schema, const Channel& channel) {
  std::scoped_lock lock{mutex_};
  topics_.emplace_back(schema, channel);
  return topics_.size() - 1;
}

void Recorder::add_metadata(const Metadata& metadata) {
  std::scoped_lock lock{mutex_};
  metadata_.push_back(metadata);
}

void Recorder::lost(std::size_t topic, std::uint64_t so_far) { push({true, topic, so_far, 0, 0, 0, {}}); }

void Recorder::write(std::size_t topic, std::uint32_t sequence, std::uint64_t log_time, std::uint64_t publish_time,
                     std::vector<std::byte> data) {
  push({false, topic, 0, sequence, log_time, publish_time, std::move(data)});
}

namespace {
// A batch is handed over at this size (or a quarter of the queue's
// limit, if less) or count, or on flush().
constexpr std::size_t kBatchBytes = 256 << 10, kBatchItems = 1024;
}  // namespace

void Recorder::push(Item item) {
  if (closed_) throw Failure{{Errc::invalid_argument, "recording '" + path_ + "': closed"}};
  batch_bytes_ += item.data.size();
  batch_.push_back(std::move(item));
  if (batch_bytes_ >= std::min(kBatchBytes, options_.max_queued / 4) || batch_.size() >= kBatchItems) flush();
}

void Recorder::flush() {
  if (batch_.empty()) return;
  std::unique_lock lock{mutex_};
  // Waits for room, but never for an empty queue: a batch larger than the
  // limit still goes, alone.
  changed_.wait(lock, [&] { return error_ || queued_ == 0 || queued_ + batch_bytes_ <= options_.max_queued; });
  if (error_) std::rethrow_exception(error_);
  queued_ += batch_bytes_;
  most_queued_ = std::max(most_queued_, queued_);
  if (queue_.empty()) {
    queue_.swap(batch_);
  } else {
    std::ranges::move(batch_, std::back_inserter(queue_));
    batch_.clear();
  }
  batch_bytes_ = 0;
  changed_.notify_all();
}

void Recorder::close() {
  if (closed_) return;
  closed_ = true;
  std::exception_ptr flushing;
  try {
    flush();
  } catch (...) {
    flushing = std::current_exception();
  }
  {
    std::scoped_lock lock{mutex_};
    closing_ = true;
    changed_.notify_all();
  }
  writer_.join();
  if (flushing) std::rethrow_exception(flushing);
  std::scoped_lock lock{mutex_};
  if (error_) std::rethrow_exception(error_);
}

void Recorder::run() {
  // Below the reading thread: when they share a CPU, the reading (which
  // loses what a ring overwrites) goes first, the writing (which has the
  // queue to fall behind into) after.
  ::setpriority(PRIO_PROCESS, static_cast<id_t>(::gettid()), ::getpriority(PRIO_PROCESS, 0) + 5);
  try {
    std::vector<Item> taken;
    for (;;) {
      {
        std::unique_lock lock{mutex_};
        changed_.wait(lock, [&] { return closing_ || !queue_.empty(); });
        if (queue_.empty()) break;  // closing, and all written
        taken.clear();
        taken.swap(queue_);
      }
      // Every topic of the batch was added before its messages were queued.
      catch_up();
      std::size_t bytes = 0, messages = 0;
      for (auto& item : taken) {
        messages += write_item(item) ? 1 : 0;
        bytes += item.data.size();
      }
      std::scoped_lock lock{mutex_};
      queued_ -= bytes;
      messages_ += messages;
      changed_.notify_all();
    }
    end_file();
  } catch (...) {
    std::scoped_lock lock{mutex_};
    error_ = std::current_exception();
    changed_.notify_all();
  }
}

bool Recorder::write_item(Item& item) {
  if (item.is_loss) {
    if (lost_.size() <= item.topic) {
      lost_.resize(item.topic + 1, 0);
      lost_at_start_.resize(item.topic + 1, 0);
    }
    lost_[item.topic] = item.lost;
    return false;
  }
  const bool full = options_.max_size > 0 && file_->bytes_written() >= options_.max_size;
  const bool long_enough = options_.max_duration > 0 && file_messages_ > 0 && item.log_time >= file_first_log_ &&
                           item.log_time - file_first_log_ >= options_.max_duration;
  if (full || long_enough) {
    end_file();
    begin_file();
  }
  if (file_messages_++ == 0) file_first_log_ = item.log_time;
  file_->write(channel_ids_.at(item.topic), item.sequence, item.log_time, item.publish_time, item.data);
  return true;
}

void Recorder::begin_file() {
  const bool split = options_.max_size > 0 || options_.max_duration > 0;
  std::string name;
  {
    std::scoped_lock lock{mutex_};
    name = split ? numbered_path(path_, files_.size()) : path_;
  }
  file_ = std::make_unique<McapWriter>(name, options_.file);
  {
    std::scoped_lock lock{mutex_};
    files_.push_back(name);
  }
  schema_ids_.clear();
  channel_ids_.clear();
  metadata_written_ = 0;
  file_messages_ = 0;
  lost_at_start_ = lost_;
  catch_up();
}

void Recorder::catch_up() {
  std::vector<std::pair<Schema, Channel>> topics;
  std::vector<Metadata> metadata;
  {
    std::scoped_lock lock{mutex_};
    topics.assign(topics_.begin() + static_cast<std::ptrdiff_t>(channel_ids_.size()), topics_.end());
    metadata.assign(metadata_.begin() + static_cast<std::ptrdiff_t>(metadata_written_), metadata_.end());
  }
  for (const auto& [schema, channel] : topics) {
    auto id = schema_ids_.find(schema.name);
    if (id == schema_ids_.end()) id = schema_ids_.emplace(schema.name, file_->add_schema(schema.name, schema.encoding, schema.data)).first;
    channel_ids_.push_back(file_->add_channel(id->second, channel.topic, channel.message_encoding, channel.metadata));
  }
  for (const auto& m : metadata) file_->add_metadata(m.name, m.values);
  metadata_written_ += metadata.size();
}

void Recorder::end_file() {
  std::map<std::string, std::string> losses;
  for (std::size_t t = 0; t < channel_ids_.size(); ++t) {
    std::string topic;
    {
      std::scoped_lock lock{mutex_};
      topic = topics_[t].second.topic;
    }
    const auto now = t < lost_.size() ? lost_[t] : 0;
    const auto before = t < lost_at_start_.size() ? lost_at_start_[t] : 0;
    losses[topic] = std::to_string(now - before);
  }
  file_->add_metadata(kLossesMetadata, losses);
  file_->close();
  std::scoped_lock lock{mutex_};
  bytes_done_ += file_->bytes_written();
}

std::vector<std::string> Recorder::files() const {
  std::scoped_lock lock{mutex_};
  return files_;
}
std::uint64_t Recorder::bytes_written() const {
  std::scoped_lock lock{mutex_};
  return bytes_done_;
}
std::uint64_t Recorder::messages_written() const {
  std::scoped_lock lock{mutex_};
  return messages_;
}
std::size_t Recorder::most_queued() const {
  std::scoped_lock lock{mutex_};
  return most_queued_;
}

}  // namespace prime::record
