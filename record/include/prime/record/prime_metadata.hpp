#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>

#include "prime/common/fingerprint.hpp"
#include "prime/record/cdr.hpp"
#include "prime/record/mcap.hpp"

namespace prime::record {

// What Prime writes into a recording beside MCAP's own records, and reads
// back: one place for both sides.

// Metadata records.
inline constexpr auto kClockMetadata = "prime.clock";    // steady_to_unix_ns: added to each steady stamp
inline constexpr auto kLossesMetadata = "prime.losses";  // per topic: samples overwritten before the recorder read them

// A channel's metadata entries that carry its type's whole fingerprint,
// so a topic can be made again with the type its readers will open.
[[nodiscard]] std::map<std::string, std::string> fingerprint_metadata(const Fingerprint& type);
// The fingerprint channel `channel` was recorded with, checked against
// the type it names (recorded_type); nullopt for a channel
// recorded without one. Throws Failure (Errc::damaged, naming `file`)
// when the entries are malformed or disagree with that type.
[[nodiscard]] std::optional<Fingerprint> recorded_fingerprint(const Summary& summary, const Channel& channel,
                                                             const std::string& file);

// A channel's metadata entry with the type's description (schema_of's
// text), for a channel whose schema is its ros2msg definition instead.
inline constexpr auto kDescriptionEntry = "prime_description";
// A channel recorded from Optimus: its entry with the type as Optimus's
// registry keeps it ("<hash> <description>"), for `prime play --redis` to
// register the source with.
inline constexpr auto kOptimusTypeEntry = "optimus_type";
// Its entry with the type's Fingerprint::describe().
inline constexpr auto kTypeEntry = "type";

// The type a channel's samples are, as a Fingerprint's describe(): its
// metadata entry, or (written before there was one) its schema's name;
// "bytes of no type" for a channel with neither.
[[nodiscard]] std::string recorded_type(const Summary& summary, const Channel& channel);

// For a channel recorded in CDR (message encoding "cdr"), the codec that
// turns its messages back into the type's `size` bytes; nullopt for one
// recorded as the bytes themselves ("prime-raw"). Throws Failure naming
// `file`: Errc::damaged for a CDR channel without a usable description,
// type_mismatch for another encoding (an Optimus source's messages, say).
[[nodiscard]] std::optional<CdrCodec> recorded_codec(const Channel& channel, std::size_t size, const std::string& file);

// What a recording's stamps (steady_clock, as published) were shifted by
// to be written as Unix time; 0 when it says nothing. Throws Failure
// (Errc::damaged) when it is no number.
[[nodiscard]] std::int64_t steady_to_unix_ns(const Summary& summary, const std::string& file);

}  // namespace prime::record
