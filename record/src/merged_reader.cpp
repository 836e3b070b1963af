// Recordings read as one timeline: chunks loaded in the order of their
// first log times, each only once the messages held so far are not sooner.
#include "prime/record/merged_reader.hpp"

#include <algorithm>

namespace prime::record {

namespace {
// The heap's order: the soonest on top.
bool later(const auto& a, const auto& b) { return a.log_time != b.log_time ? a.log_time > b.log_time : a.order > b.order; }
}  // namespace

MergedReader::MergedReader(const std::vector<std::string>& files) {
  if (files.empty()) throw Failure{{Errc::invalid_argument, "no recording given"}};
  bool any = false;
  for (std::size_t f = 0; f < files.size(); ++f) {
    paths_.push_back(files[f]);
    files_.push_back(std::make_unique<McapReader>(files[f]));
    const auto& s = files_.back()->summary();
    for (const auto& c : s.chunks) chunks_.push_back({c.message_start_time, c.message_end_time, f, &c});
    if (s.statistics.message_count == 0) continue;
    start_ = any ? std::min(start_, s.statistics.message_start_time) : s.statistics.message_start_time;
    end_ = any ? std::max(end_, s.statistics.message_end_time) : s.statistics.message_end_time;
    any = true;
  }
  std::ranges::stable_sort(chunks_, [](const Chunk& a, const Chunk& b) { return a.start < b.start; });
  seek(0);
}

void MergedReader::seek(std::uint64_t from, std::uint64_t to, Wanted wanted) {
  from_ = from;
  to_ = to;
  wanted_ = std::move(wanted);
  pending_ = 0;
  heap_.clear();
  chunks_read_ = 0;
}

void MergedReader::load(const Chunk& chunk) {
  ++chunks_read_;
  files_[chunk.file]->for_each_message_in(*chunk.info, [&](const Message& m) {
    if (m.log_time < from_ || m.log_time > to_) return;
    if (wanted_ && !wanted_(chunk.file, m.channel_id)) return;
    heap_.push_back({m.log_time, loaded_++, chunk.file, m});
    std::ranges::push_heap(heap_, [](const Held& a, const Held& b) { return later(a, b); });
  });
}

std::optional<MergedReader::Next> MergedReader::next() {
  // A chunk that starts no later than the soonest message held may hold
  // one sooner still: load it first. Chunks that end before `from_` are
  // passed by their index entry alone.
  while (pending_ < chunks_.size() && (heap_.empty() || chunks_[pending_].start <= heap_.front().log_time)) {
    const auto& chunk = chunks_[pending_++];
    if (chunk.start > to_) {
      pending_ = chunks_.size();  // by their first times: every later chunk starts later still
      break;
    }
    if (chunk.end < from_) continue;
    load(chunk);
  }
  if (heap_.empty()) return std::nullopt;
  std::ranges::pop_heap(heap_, [](const Held& a, const Held& b) { return later(a, b); });
  Next out{heap_.back().file, std::move(heap_.back().message)};
  heap_.pop_back();
  return out;
}

}  // namespace prime::record
