// The last seconds of a recording in memory, written into a file when asked.
#include "prime/record/snapshot_recorder.hpp"

#include "prime/record/prime_metadata.hpp"
#include "prime/topology/detail/quiet_threads.hpp"

namespace prime::record {

SnapshotRecorder::SnapshotRecorder(std::string path, RecorderOptions options, std::uint64_t window, std::size_t max_bytes)
    : path_{std::move(path)}, options_{std::move(options)}, window_{window}, max_bytes_{max_bytes} {}

SnapshotRecorder::~SnapshotRecorder() {
  try {
    close();
  } catch (const Failure&) {
  }
}

std::size_t SnapshotRecorder::add_topic(const Schema& schema, const Channel& channel) {
  topics_.emplace_back(schema, channel);
  lost_at_start_.push_back(0);
  return topics_.size() - 1;
}

void SnapshotRecorder::add_metadata(const Metadata& metadata) { metadata_.push_back(metadata); }

void SnapshotRecorder::lost(std::size_t topic, std::uint64_t so_far) {
  held_.push_back({true, topic, so_far, 0, 0, newest_, {}});
}

void SnapshotRecorder::write(std::size_t topic, std::uint32_t sequence, std::uint64_t log_time, std::uint64_t publish_time,
                             std::vector<std::byte> data) {
  newest_ = std::max(newest_, publish_time);
  bytes_ += data.size();
  held_.push_back({false, topic, 0, sequence, log_time, publish_time, std::move(data)});
  trim();
}

void SnapshotRecorder::trim() {
  // Older than the window, or beyond the memory bound: let go, oldest
  // first. A loss let go moves the window's start count.
  while (!held_.empty() && (held_.front().publish_time + window_ < newest_ || bytes_ > max_bytes_)) {
    auto& h = held_.front();
    if (h.is_loss) lost_at_start_[h.topic] = h.lost;
    bytes_ -= h.data.size();
    held_.pop_front();
  }
}

std::uint64_t SnapshotRecorder::held_span() const noexcept {
  for (const auto& h : held_)
    if (!h.is_loss) return newest_ - h.publish_time;
  return 0;
}

std::pair<std::string, std::size_t> SnapshotRecorder::take() {
  if (closed_) throw Failure{{Errc::invalid_argument, "recording '" + path_ + "': closed"}};
  auto options = options_;
  options.max_size = options.max_duration = 0;
  const auto name = numbered_path(path_, files_.size());
  auto w = std::make_unique<Writing>();
  w->recorder = std::make_unique<Recorder>(name, options);
  files_.push_back(name);
  for (const auto& m : metadata_) w->recorder->add_metadata(m);
  for (const auto& [schema, channel] : topics_) w->recorder->add_topic(schema, channel);
  std::size_t messages = 0;
  for (const auto& h : held_) {
    if (h.is_loss) {
      w->recorder->lost(h.topic, h.lost - lost_at_start_[h.topic]);
    } else {
      w->recorder->write(h.topic, h.sequence, h.log_time, h.publish_time, h.data);
      ++messages;
    }
  }
  w->recorder->flush();
  auto* writing = w.get();
  w->closing = prime::detail::with_signals_blocked([writing] {
    return std::thread{[writing] {
      try {
        writing->recorder->close();
      } catch (...) {
        writing->error = std::current_exception();
      }
    }};
  });
  writing_.push_back(std::move(w));
  return {name, messages};
}

void SnapshotRecorder::close() {
  if (closed_) return;
  closed_ = true;
  std::exception_ptr first;
  for (auto& w : writing_) {
    if (w->closing.joinable()) w->closing.join();
    if (w->error && !first) first = w->error;
  }
  if (first) std::rethrow_exception(first);
}

std::uint64_t SnapshotRecorder::bytes_written() const {
  std::uint64_t n = 0;
  for (const auto& w : writing_) n += w->recorder->bytes_written();
  return n;
}

}  // namespace prime::record
