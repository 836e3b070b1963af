#pragma once

#include <algorithm>
#include <charconv>
#include <chrono>
#include <cstdint>
#include <deque>
#include <map>
#include <optional>
#include <string>
#include <string_view>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"
#include "prime/optimus/detail/connection.hpp"
#include "prime/optimus/detail/keys.hpp"
#include "prime/optimus/detail/stream_protocol.hpp"
#include "prime/optimus/options.hpp"

namespace prime::optimus {

// Looking at an Optimus domain from outside, for tools: what its registry
// lists, how long each source's stream is, who reads it, which services
// are alive, and the entries a source appends from now on. Nothing here
// registers, reads as a reader or takes a request.

struct SourceSummary {
  std::string name;
  std::string type;           // its type, as the registry describes it
  std::string stream;         // the stream's key
  long long length = 0;       // entries in the stream now
  long long readers = 0;      // readers registered (live leases)
};

struct ServiceSummary {
  std::string name;
  std::string types;  // request and reply, as the registry describes them
  bool alive = false;  // a server refreshed its alive key lately
};

// An entry of a source's stream.
struct StreamEntry {
  std::optional<std::uint64_t> sequence{};       // none in an entry not Prime's
  std::optional<Clock::time_point> stamp{};      // its sensor's; none in an entry not Prime's
  std::string data{};                            // the message's bytes
};

// One connection to the server of `options` (its URL, credentials and
// connect timeout), looking at domain `options.domain`. Each call throws
// Failure: Errc::unreachable (the server, or a reply it refused).
class Inspector {
 public:
  explicit Inspector(Options options) : options_{std::move(options)}, connection_{open(options_)} {}

  // The server as errors show it: its URL without a password.
  [[nodiscard]] std::string server() const { return detail::without_password(options_.url); }

  [[nodiscard]] std::vector<SourceSummary> sources() {
    std::vector<SourceSummary> out;
    for (auto& [name, record] : hash(detail::sources_key(options_.domain))) {
      auto stream = detail::stream_key(options_.domain, name);
      const auto length = integer({"XLEN", stream});
      out.push_back({name, described(record), std::move(stream), length, readers(name)});
    }
    return out;
  }

  [[nodiscard]] std::vector<ServiceSummary> services() {
    std::vector<ServiceSummary> out;
    for (auto& [name, record] : hash(detail::services_key(options_.domain)))
      out.push_back({name, described(record),
                     integer({"EXISTS", detail::alive_key(detail::service_key(options_.domain, name))}) != 0});
    return out;
  }

  // The entries appended to a source's stream from when it is made, one
  // at a time (read a hundred at a time). Lives no longer than its Inspector.
  class Tail {
   public:
    // The next entry, waiting for it up to `timeout`.
    std::optional<StreamEntry> next(Clock::duration timeout) {
      if (buffered_.empty()) {
        // At least 1 ms: BLOCK 0 would wait for ever.
        const auto ms = std::max<long long>(1, std::chrono::duration_cast<std::chrono::milliseconds>(timeout).count());
        auto reply = inspector_->command({"XREAD", "COUNT", "100", "BLOCK", std::to_string(ms), "STREAMS", stream_, last_});
        if (reply->is_array() && reply->size() > 0) read((*reply)[0]);
      }
      if (buffered_.empty()) return std::nullopt;
      auto front = std::move(buffered_.front());
      buffered_.pop_front();
      return front;
    }

   private:
    friend class Inspector;
    Tail(Inspector& inspector, std::string stream) : inspector_{&inspector}, stream_{std::move(stream)} {}

    // [stream, [[id, [field, value, ...]], ...]]: checked, since another
    // process wrote it.
    void read(detail::ReplyRef stream) {
      if (!stream.is_array() || stream.size() < 2 || !stream[1].is_array()) return;
      const auto entries = stream[1];
      for (std::size_t i = 0; i < entries.size(); ++i) {
        const auto e = entries[i];
        if (!e.is_array() || e.size() < 2 || !e[0].is_string()) continue;
        const std::string id{e[0].text()};
        last_ = id;
        StreamEntry out;
        if (const auto parsed = detail::entry_id(id)) out.sequence = parsed->seq;
        const auto fields = e[1];
        if (fields.is_array())
          for (std::size_t f = 0; f + 1 < fields.size(); f += 2) {
            const auto name = fields[f].text();
            const auto value = fields[f + 1].text();
            if (name == "d") out.data = std::string{value};
            std::int64_t ns = 0;
            if (name == "t" && std::from_chars(value.data(), value.data() + value.size(), ns).ec == std::errc{})
              out.stamp = Clock::time_point{std::chrono::nanoseconds{ns}};
          }
        buffered_.push_back(std::move(out));
      }
    }

    Inspector* inspector_;
    std::string stream_;
    std::string last_ = "$";
    std::deque<StreamEntry> buffered_;
  };

  [[nodiscard]] Tail tail(const std::string& source) { return Tail{*this, detail::stream_key(options_.domain, source)}; }

 private:
  static detail::Connection open(const Options& options) {
    const auto endpoint = detail::parse_url(options.url);
    if (!endpoint) throw Failure{endpoint.error()};
    auto connection = detail::Connection::open(options, *endpoint);
    if (!connection) throw Failure{connection.error()};
    return std::move(*connection);
  }

  // The reply to `words`, or a Failure naming what went wrong.
  detail::Reply command(const std::vector<std::string>& words) {
    const std::vector<std::string_view> args(words.begin(), words.end());
    auto reply = connection_.command(args);
    if (!reply) throw Failure{reply.error()};
    if ((*reply)->is_error())
      throw Failure{{Errc::unreachable, "redis at " + server() + ": " + std::string{(*reply)->text()}}};
    return std::move(*reply);
  }

  std::map<std::string, std::string> hash(const std::string& key) {
    std::map<std::string, std::string> out;
    auto reply = command({"HGETALL", key});
    if (!reply->is_array()) return out;
    for (std::size_t i = 0; i + 1 < reply->size(); i += 2)
      out[std::string{(*reply)[i].text()}] = std::string{(*reply)[i + 1].text()};
    return out;
  }

  long long integer(const std::vector<std::string>& words) {
    auto reply = command(words);
    return reply->integer();
  }

  // A source's readers: the "r<id>" fields of its readers hash (a reader
  // that has lost values also has an "l<id>" field there).
  long long readers(const std::string& source) {
    auto reply = command({"HKEYS", detail::readers_key(options_.domain, source)});
    long long n = 0;
    for (std::size_t i = 0; i < reply->size(); ++i)
      if ((*reply)[i].text().starts_with('r')) ++n;
    return n;
  }

  // "0123456789abcdef Pose (24 bytes, ...)" -> "Pose (24 bytes, ...)"
  static std::string described(const std::string& record) {
    const auto space = record.find(' ');
    return space == std::string::npos ? record : record.substr(space + 1);
  }

  Options options_;
  detail::Connection connection_;
};

}  // namespace prime::optimus
