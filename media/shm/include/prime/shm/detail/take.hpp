#pragma once

#include <atomic>
#include <cstddef>
#include <cstdint>
#include <optional>

#include "prime/shm/detail/layout.hpp"
#include "prime/shm/detail/prefetch.hpp"
#include "prime/shm/detail/topic.hpp"

namespace prime::shm::detail {

// The take protocol, the one every reader path follows (Cursor's try_take,
// take_some and take_batch): look, then hold and verify.
//
// 1. look(seq): the ring entry for `seq` and, beside it, the sample's size
//    and stamp (SampleInfo), read before the hold's check.
// 2. hold(seq, chunk): the reader's bit set in the chunk's holders, then
//    the ring entry loaded again. The hold counts only if the entry still
//    names the chunk for `seq`; else the bit is taken back and nothing of
//    the chunk is read. With the publisher's eviction (ChunkPool::evict) that
//    is Dekker's: either the publisher sees the bit and keeps the chunk
//    from reuse, or the reader sees the entry replaced.
// A path taking several samples looks at all of them first (their lines
// travel together), then holds them in order, stopping at the first whose
// check fails.

// A sample's size and stamp, as read when it was taken.
struct TakenInfo {
  std::uint64_t size;
  std::int64_t stamp;
};

// A sample taken by a subscriber: its chunk, held by the subscriber's bit
// until released.
struct Taken {
  std::uint32_t chunk;
  std::uint64_t seq;
  TakenInfo info;
};

// Sample `seq`'s size and stamp, read beside the ring as SampleInfo says;
// none when they are not its own (the publisher is overwriting them: the
// sample is lost).
inline std::optional<TakenInfo> info_of(const Places& places, std::uint64_t seq) noexcept {
  const auto& info = places.info(seq);
  const auto word = info.word.load(std::memory_order_acquire);
  const auto stamp = info.stamp.load(std::memory_order_acquire);
  if (info.word.load(std::memory_order_acquire) != word || !SampleInfo::names(word, seq)) return std::nullopt;
  return TakenInfo{places.size(SampleInfo::size_of(word)), stamp};
}

// What a look at one ring entry found.
struct Look {
  enum class Is : std::uint8_t {
    out,      // sample `seq` is there, in `chunk`, described by `info`
    not_yet,  // the entry still carries an older sample: nothing new
    gone,     // overwritten, being overwritten, or damaged: not to be taken
  };
  Is is;
  std::uint32_t chunk = 0;
  TakenInfo info{};
};

// Step 1. The chunk's header line is asked for, for writing, when
// `for_hold` (a hold follows), and its payload once the sample is found.
inline Look look(const Places& places, std::uint64_t seq, bool for_hold) noexcept {
  const auto entry = places.ring(seq).load(std::memory_order_acquire);
  const auto ahead = RingEntry::ahead(entry, seq);
  if (ahead < 0) return {Look::Is::not_yet};
  if (ahead > 0 || !places.names_chunk(entry)) return {Look::Is::gone};
  const auto chunk = RingEntry::chunk(entry);
  if (for_hold) prefetch_for_write(&places.chunk(chunk));
  const auto info = info_of(places, seq);
  if (!info) return {Look::Is::gone};
  __builtin_prefetch(places.payload(chunk));
  return {Look::Is::out, chunk, *info};
}

// Step 2: whether `bit` now holds `chunk` for sample `seq`.
inline bool hold(const Places& places, std::uint64_t bit, std::uint64_t seq, std::uint32_t chunk) noexcept {
  auto& holders = places.chunk(chunk).holders;
  holders.fetch_or(bit, std::memory_order_seq_cst);
  if (places.ring(seq).load(std::memory_order_seq_cst) == RingEntry::pack(seq, chunk)) return true;
  holders.fetch_and(~bit);
  return false;
}

// Step 2 for samples first, first + 1, ... in chunk_at(0), chunk_at(1), ...:
// how many of the first `n` are held, in order, up to the first that is not.
template <class ChunkAt>
std::size_t hold_in_order(const Places& places, std::uint64_t bit, std::uint64_t first, std::size_t n,
                          ChunkAt&& chunk_at) noexcept {
  for (std::size_t i = 0; i < n; ++i)
    if (!hold(places, bit, first + i, chunk_at(i))) return i;
  return n;
}

}  // namespace prime::shm::detail
