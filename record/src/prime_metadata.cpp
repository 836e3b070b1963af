// Prime's own entries in a recording: the clock, the losses, a topic's fingerprint.
#include "prime/record/prime_metadata.hpp"

#include <charconv>
#include <cstring>

namespace prime::record {

namespace {

constexpr auto kName = "type_name", kSize = "type_size", kAlignment = "type_alignment", kLayout = "type_layout",
               kHash = "type_hash";

template <class N>
std::optional<N> number(const std::string& text, int base = 10) {
  N n{};
  const auto [end, error] = std::from_chars(text.data(), text.data() + text.size(), n, base);
  if (error != std::errc{} || end != text.data() + text.size()) return std::nullopt;
  return n;
}

}  // namespace

std::map<std::string, std::string> fingerprint_metadata(const Fingerprint& type) {
  char hash[17];
  std::snprintf(hash, sizeof hash, "%016llx", static_cast<unsigned long long>(type.hash));
  return {{kName, read_text(type.name)},
          {kSize, std::to_string(type.size)},
          {kAlignment, std::to_string(type.alignment)},
          {kLayout, std::to_string(type.layout_version)},
          {kHash, hash}};
}

std::optional<Fingerprint> recorded_fingerprint(const Summary& summary, const Channel& channel, const std::string& file) {
  const auto& m = channel.metadata;
  if (!m.contains(kHash)) return std::nullopt;
  auto damaged = [&](const std::string& why) {
    return Failure{{Errc::damaged, "recording '" + file + "': topic '" + channel.topic + "': " + why}};
  };
  auto entry = [&](const char* key) {
    const auto it = m.find(key);
    if (it == m.end()) throw damaged(std::string{"its type's fingerprint has no "} + key);
    return it->second;
  };
  Fingerprint f;
  const auto name = entry(kName);
  if (name.size() >= Fingerprint::kNameCapacity) throw damaged("its type's name is longer than a fingerprint holds");
  std::memcpy(f.name, name.data(), name.size());
  const auto size = number<std::uint64_t>(entry(kSize));
  const auto alignment = number<std::uint64_t>(entry(kAlignment));
  const auto layout = number<std::uint32_t>(entry(kLayout));
  const auto hash = number<std::uint64_t>(entry(kHash), 16);
  if (!size || !alignment || !layout || !hash) throw damaged("its type's fingerprint has a field that is no number");
  f.size = *size;
  f.alignment = *alignment;
  f.layout_version = *layout;
  f.hash = *hash;
  if (recorded_type(summary, channel) != f.describe())
    throw damaged("its type's fingerprint (" + f.describe() + ") is not the type it names (" + recorded_type(summary, channel) + ")");
  return f;
}

std::string recorded_type(const Summary& summary, const Channel& channel) {
  if (const auto it = channel.metadata.find(kTypeEntry); it != channel.metadata.end()) return it->second;
  const auto schema = summary.schemas.find(channel.schema_id);
  return schema == summary.schemas.end() ? std::string{"bytes of no type"} : schema->second.name;
}

std::optional<CdrCodec> recorded_codec(const Channel& channel, std::size_t size, const std::string& file) {
  if (channel.message_encoding == "prime-raw") return std::nullopt;
  if (channel.message_encoding != "cdr")
    throw Failure{{Errc::type_mismatch, "recording '" + file + "': topic '" + channel.topic + "' is in message encoding '" +
                                            channel.message_encoding + "', not a type's bytes or CDR"}};
  const auto it = channel.metadata.find(kDescriptionEntry);
  auto codec = it == channel.metadata.end() ? std::nullopt : CdrCodec::of(it->second, size);
  if (!codec)
    throw Failure{{Errc::damaged, "recording '" + file + "': topic '" + channel.topic +
                                      "' is in CDR without a description of its type that fits its " + std::to_string(size) +
                                      " bytes"}};
  return codec;
}

std::int64_t steady_to_unix_ns(const Summary& summary, const std::string& file) {
  for (const auto& m : summary.metadata)
    if (m.name == kClockMetadata)
      if (const auto v = m.values.find("steady_to_unix_ns"); v != m.values.end()) {
        if (const auto n = number<std::int64_t>(v->second)) return *n;
        throw Failure{{Errc::damaged, "recording '" + file + "': its clock offset '" + v->second + "' is no number"}};
      }
  return 0;
}

}  // namespace prime::record
