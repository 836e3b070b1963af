#pragma once

#include <charconv>
#include <chrono>
#include <cstddef>
#include <cstdint>
#include <optional>
#include <string>
#include <string_view>
#include <system_error>

#include "prime/logic/sample.hpp"
#include "prime/optimus/detail/connection.hpp"

// How a source lives on the server, as its writers and readers agree on it:
// the ids and fields of an entry, the script that appends one at a time, and
// what a reader keeps in the source's readers hash. The writing side is
// stream_writer.hpp, the reading side stream_reader.hpp.
//
// An entry's id is "<epoch>-<k>": the epoch is the server's time (ms) when
// the stream began, and every writer appends with "<epoch>-*", so the server
// numbers entries 0, 1, 2 … atomically across writers. The entry's sequence
// number is k + 1; a reader counts what trimming took from it by the gaps.
// A stream that begins again (deleted, or lost in a restart without
// persistence) gets a new, later epoch: a reader's cursor in the old one
// still comes before every new entry, and the reader sees the epoch change.
// Fields: t the sensor stamp (steady clock, ns), d the encoded message, and
// x, for a `block` source, the readers the entry was dropped for (",id,id,")
// because they made no room in time.

namespace prime::optimus::detail {

// Appends one entry to a source's stream, atomically on the server, in the
// epoch of its last entry (a new one, the server's time, when it has none).
// The stream is trimmed to exactly ARGV[1] entries. Mode ARGV[4]: "drop"
// appends; "wait" appends only if every registered reader has room and
// otherwise returns {0, full}; "force" appends and marks the full readers;
// "sweep" appends nothing (a reader subscribing: below).
// A reader whose lease (the key ARGV[5] .. id) has run out is gone: a
// process that died, or one that has not read for kReaderLease. Every mode
// but "drop" strikes its fields from the readers hash once it would be
// waited for (its room is used up), so that no writer waits for it and a
// killed reader leaves nothing behind for longer than it takes the stream
// to pass it (fields have no TTL of their own). A reader with room is left
// alone: one that only paused reads on as if nothing happened. A struck
// reader that reads again registers again.
//   KEYS: stream, readers hash.  ARGV: maxlen, stamp, message, mode, lease prefix.
// The readers hash holds, per reader id, "r<id>" = reader_progress() and
// "l<id>" = how many values were dropped for it.
inline constexpr std::string_view kPublishScript = R"lua(
local epoch, n
local last = redis.call('XREVRANGE', KEYS[1], '+', '-', 'COUNT', 1)
if #last > 0 then
  local ms, k = string.match(last[1][1], '^(%d+)-(%d+)$')
  epoch, n = ms, tonumber(k) + 2
else
  local now = redis.call('TIME')
  epoch, n = now[1] .. string.format('%03d', math.floor(tonumber(now[2]) / 1000)), 1
end
local full = {}
if ARGV[4] ~= 'drop' then
  local readers = redis.call('HGETALL', KEYS[2])
  local progress = {}
  for i = 1, #readers, 2 do
    if string.sub(readers[i], 1, 1) == 'r' then progress[string.sub(readers[i], 2)] = readers[i + 1] end
  end
  for i = 1, #readers, 2 do
    local id = string.sub(readers[i], 2)
    local cursor, capacity = string.match(progress[id] or '', '^(%d+) (%d+)$')
    local behind = cursor ~= nil and n - tonumber(cursor) > tonumber(capacity)
    if (behind or cursor == nil) and redis.call('EXISTS', ARGV[5] .. id) == 0 then
      redis.call('HDEL', KEYS[2], readers[i])
    elseif behind and string.sub(readers[i], 1, 1) == 'r' then
      full[#full + 1] = id
    end
  end
  if ARGV[4] == 'sweep' then return {0, 0} end
  if #full > 0 and ARGV[4] == 'wait' then return {0, #full} end
end
if #full > 0 then
  for _, reader in ipairs(full) do redis.call('HINCRBY', KEYS[2], 'l' .. reader, 1) end
  redis.call('XADD', KEYS[1], 'MAXLEN', ARGV[1], epoch .. '-*', 't', ARGV[2], 'd', ARGV[3], 'x', ',' .. table.concat(full, ',') .. ',')
else
  redis.call('XADD', KEYS[1], 'MAXLEN', ARGV[1], epoch .. '-*', 't', ARGV[2], 'd', ARGV[3])
end
return {1, #full}
)lua";

// The script's modes (ARGV[4]).
inline constexpr std::string_view kAppendDrop = "drop";
inline constexpr std::string_view kAppendWait = "wait";
inline constexpr std::string_view kAppendForce = "force";
inline constexpr std::string_view kSweepOnly = "sweep";

inline std::int64_t stamp_ns(Clock::time_point t) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(t.time_since_epoch()).count();
}

template <class N>
bool parse_number(std::string_view text, N& out) {
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), out);
  return ec == std::errc{} && end == text.data() + text.size();
}

// An entry's id: its stream's epoch and its sequence number.
struct EntryId {
  std::uint64_t epoch = 0;
  std::uint64_t seq = 0;  // k + 1 for the id "<epoch>-<k>"
};
inline std::optional<EntryId> entry_id(std::string_view id) {
  const auto dash = id.find('-');
  EntryId out;
  std::uint64_t k = 0;
  if (dash == std::string_view::npos || !parse_number(id.substr(0, dash), out.epoch) ||
      !parse_number(id.substr(dash + 1), k))
    return std::nullopt;
  out.seq = k + 1;
  return out;
}

// What a writer appends with in a stream's epoch: the server numbers the entry.
inline std::string append_id(std::uint64_t epoch) { return std::to_string(epoch) + "-*"; }

// An epoch from a reply of TIME: the server's time in ms.
inline std::optional<std::uint64_t> epoch_from_time(ReplyRef time) {
  std::uint64_t seconds = 0, micros = 0;
  if (!time.is_array() || time.size() != 2 || !parse_number(text(time[0]), seconds) ||
      !parse_number(text(time[1]), micros))
    return std::nullopt;
  return seconds * 1000 + micros / 1000;
}

// A reader's fields in the readers hash.
inline std::string reader_field(std::string_view reader_id) { return "r" + std::string{reader_id}; }
// A `block` reader's lease: a key that lives kReaderLease after the reader
// last read or waited (each refreshes it). Writers strike a reader whose
// lease ran out from the readers hash; the reader's next read registers it
// again.
inline constexpr std::chrono::milliseconds kReaderLease{3000};
inline std::string lease_prefix(std::string_view readers_key) { return std::string{readers_key} + ":lease:"; }
inline std::string lease_key(std::string_view readers_key, std::string_view reader_id) {
  return lease_prefix(readers_key) + std::string{reader_id};
}
inline std::string lost_field(std::string_view reader_id) { return "l" + std::string{reader_id}; }
// What a `block` reader registers: the sequence number it has read up to and
// how many more it has room for.
inline std::string reader_progress(std::uint64_t seq, std::string_view capacity) {
  return std::to_string(seq) + " " + std::string{capacity};
}

// A field of an entry, from its reply's [field, value, ...] array.
inline std::optional<std::string_view> entry_field(ReplyRef fields, std::string_view name) {
  if (!fields.is_array()) return std::nullopt;
  for (std::size_t i = 0; i + 1 < fields.size(); i += 2)
    if (text(fields[i]) == name) return text(fields[i + 1]);
  return std::nullopt;
}

// One entry of a stream reply: [id, [field, value, ...]]. Null when the reply
// has another shape.
struct StreamEntry {
  std::string_view id;
  ReplyRef fields;
};
inline std::optional<StreamEntry> stream_entry(ReplyRef entry) {
  if (!entry.is_array() || entry.size() != 2) return std::nullopt;
  return StreamEntry{text(entry[0]), entry[1]};
}

// An entry's fields as Prime's writers write them. Null when t or d is
// missing or not what Prime writes (not a Prime entry).
struct EntryFields {
  std::int64_t stamp_ns = 0;
  std::string_view message;
  std::optional<std::string_view> dropped_for;  // x

  // Whether a writer dropped this value for the reader `reader_id`.
  [[nodiscard]] bool dropped_for_reader(std::string_view reader_id) const {
    return dropped_for && dropped_for->find("," + std::string{reader_id} + ",") != std::string_view::npos;
  }
};
inline std::optional<EntryFields> entry_fields(ReplyRef fields) {
  EntryFields out;
  const auto t = entry_field(fields, "t");
  const auto d = entry_field(fields, "d");
  if (!t || !parse_number(*t, out.stamp_ns) || !d) return std::nullopt;
  out.message = *d;
  out.dropped_for = entry_field(fields, "x");
  return out;
}

}  // namespace prime::optimus::detail
