#pragma once

#include <hiredis/hiredis.h>

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
// the script that appends, the fields of an entry, and what a reader keeps in
// the source's readers hash. The writing side is stream_writer.hpp, the
// reading side stream_reader.hpp.

namespace prime::optimus::detail {

// Appends one entry to a source's stream, atomically on the server:
//   n  the entry's sequence number (one more than the last entry's), so a
//      reader can count what trimming took from it;
//   t  the sensor stamp (steady clock, ns), d the encoded message;
//   x  for a `block` source, the readers this entry was dropped for
//      (",id,id,"), because they made no room in time.
// The stream is trimmed to exactly ARGV[1] entries. Mode ARGV[4]: "drop"
// appends; "wait" appends only if every registered reader has room and
// otherwise returns {0, full}; "force" appends and marks the full readers.
//   KEYS: stream, readers hash.  ARGV: maxlen, stamp, message, mode.
// The readers hash holds, per reader id, "r<id>" = reader_progress() and
// "l<id>" = how many values were dropped for it.
inline constexpr std::string_view kPublishScript = R"lua(
local n = 1
local last = redis.call('XREVRANGE', KEYS[1], '+', '-', 'COUNT', 1)
if #last > 0 then
  local previous = tonumber(last[1][2][2])
  if previous then n = previous + 1 end
end
local full = {}
if ARGV[4] ~= 'drop' then
  local readers = redis.call('HGETALL', KEYS[2])
  for i = 1, #readers, 2 do
    if string.sub(readers[i], 1, 1) == 'r' then
      local cursor, capacity = string.match(readers[i + 1], '^(%d+) (%d+)$')
      if cursor and n - tonumber(cursor) > tonumber(capacity) then full[#full + 1] = string.sub(readers[i], 2) end
    end
  end
  if #full > 0 and ARGV[4] == 'wait' then return {0, #full} end
end
if #full > 0 then
  for _, reader in ipairs(full) do redis.call('HINCRBY', KEYS[2], 'l' .. reader, 1) end
  redis.call('XADD', KEYS[1], 'MAXLEN', ARGV[1], '*', 'n', tostring(n), 't', ARGV[2], 'd', ARGV[3], 'x', ',' .. table.concat(full, ',') .. ',')
else
  redis.call('XADD', KEYS[1], 'MAXLEN', ARGV[1], '*', 'n', tostring(n), 't', ARGV[2], 'd', ARGV[3])
end
return {1, #full}
)lua";

// Appends a batch of entries in one call, as kPublishScript's "drop" mode
// would one by one (a batch never waits for readers): the last entry's n is
// read once, and the stream is trimmed once, to exactly ARGV[1] entries.
//   KEYS: stream.  ARGV: maxlen, then stamp, message for each entry.
// Returns the number of entries appended. (Both scripts pass n through
// tostring: redis.call's own conversion of a Lua number costs more.)
inline constexpr std::string_view kPublishBatchScript = R"lua(
local n = 0
local last = redis.call('XREVRANGE', KEYS[1], '+', '-', 'COUNT', 1)
if #last > 0 then
  local previous = tonumber(last[1][2][2])
  if previous then n = previous end
end
local appended = 0
for i = 2, #ARGV - 1, 2 do
  n = n + 1
  redis.call('XADD', KEYS[1], '*', 'n', tostring(n), 't', ARGV[i], 'd', ARGV[i + 1])
  appended = appended + 1
end
redis.call('XTRIM', KEYS[1], 'MAXLEN', ARGV[1])
return appended
)lua";
// Entries per call of the batch script: a pipelined batch is sent as calls
// of this many, so no call holds the server for long.
inline constexpr std::size_t kBatchEntries = 256;

// The script's modes (ARGV[4]).
inline constexpr std::string_view kAppendDrop = "drop";
inline constexpr std::string_view kAppendWait = "wait";
inline constexpr std::string_view kAppendForce = "force";

inline std::int64_t stamp_ns(Clock::time_point t) {
  return std::chrono::duration_cast<std::chrono::nanoseconds>(t.time_since_epoch()).count();
}

template <class N>
bool parse_number(std::string_view text, N& out) {
  const auto [end, ec] = std::from_chars(text.data(), text.data() + text.size(), out);
  return ec == std::errc{} && end == text.data() + text.size();
}

// A reader's fields in the readers hash.
inline std::string reader_field(std::string_view reader_id) { return "r" + std::string{reader_id}; }
inline std::string lost_field(std::string_view reader_id) { return "l" + std::string{reader_id}; }
// What a `block` reader registers: the sequence number it has read up to and
// how many more it has room for.
inline std::string reader_progress(std::uint64_t seq, std::string_view capacity) {
  return std::to_string(seq) + " " + std::string{capacity};
}

// A field of an entry, from its reply's [field, value, ...] array.
inline std::optional<std::string_view> entry_field(const redisReply& fields, std::string_view name) {
  if (fields.type != REDIS_REPLY_ARRAY) return std::nullopt;
  for (std::size_t i = 0; i + 1 < fields.elements; i += 2)
    if (text(*fields.element[i]) == name) return text(*fields.element[i + 1]);
  return std::nullopt;
}

// One entry of a stream reply: [id, [field, value, ...]]. Null when the reply
// has another shape.
struct StreamEntry {
  std::string_view id;
  const redisReply* fields;
};
inline std::optional<StreamEntry> stream_entry(const redisReply& entry) {
  if (entry.type != REDIS_REPLY_ARRAY || entry.elements != 2) return std::nullopt;
  return StreamEntry{text(*entry.element[0]), entry.element[1]};
}

// An entry's fields as the publish script writes them. Null when one of n, t
// and d is missing or not what Prime writes (not a Prime entry).
struct EntryFields {
  std::uint64_t seq = 0;
  std::int64_t stamp_ns = 0;
  std::string_view message;
  std::optional<std::string_view> dropped_for;  // x

  // Whether a writer dropped this value for the reader `reader_id`.
  [[nodiscard]] bool dropped_for_reader(std::string_view reader_id) const {
    return dropped_for && dropped_for->find("," + std::string{reader_id} + ",") != std::string_view::npos;
  }
};
inline std::optional<EntryFields> entry_fields(const redisReply& fields) {
  EntryFields out;
  const auto n = entry_field(fields, "n");
  const auto t = entry_field(fields, "t");
  const auto d = entry_field(fields, "d");
  if (!n || !parse_number(*n, out.seq) || !t || !parse_number(*t, out.stamp_ns) || !d) return std::nullopt;
  out.message = *d;
  out.dropped_for = entry_field(fields, "x");
  return out;
}

}  // namespace prime::optimus::detail
