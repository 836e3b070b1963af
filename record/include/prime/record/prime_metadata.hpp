#pragma once

#include <cstdint>
#include <map>
#include <optional>
#include <string>

#include "prime/common/fingerprint.hpp"
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
// its schema's name (a Fingerprint's describe()); nullopt for a channel
// recorded without one. Throws Failure (Errc::damaged, naming `file`)
// when the entries are malformed or disagree with the schema.
[[nodiscard]] std::optional<Fingerprint> recorded_fingerprint(const Summary& summary, const Channel& channel,
                                                             const std::string& file);

// What a recording's stamps (steady_clock, as published) were shifted by
// to be written as Unix time; 0 when it says nothing. Throws Failure
// (Errc::damaged) when it is no number.
[[nodiscard]] std::int64_t steady_to_unix_ns(const Summary& summary, const std::string& file);

}  // namespace prime::record
