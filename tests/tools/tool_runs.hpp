#pragma once

// The prime tool run as a process by the tests: to its end, its output
// read back.

#include <string>
#include <vector>

#include "json.hpp"
#include "shm/peer_process.hpp"

namespace prime::test {

struct Run {
  int code;
  std::string out;
};

// The command `argv`, to its end.
inline Run finished(std::vector<std::string> argv) {
  auto process = PeerProcess::command(std::move(argv), true);
  auto out = process.all_output();
  return {process.exit_code().value_or(-1), out};
}

// `prime --domain <domain> <args...>`, to its end.
inline Run prime(const std::string& domain, std::vector<std::string> args) {
  args.insert(args.begin(), {PRIME_TOOL_PATH, "--domain", domain});
  return finished(std::move(args));
}

// The last line of `text` that starts with '{' or '[', as JSON.
inline tool::Json last_json(const std::string& text) {
  std::string last;
  std::size_t at = 0;
  while (at < text.size()) {
    const auto nl = text.find('\n', at);
    const auto line = text.substr(at, nl == std::string::npos ? std::string::npos : nl - at);
    if (!line.empty() && (line[0] == '{' || line[0] == '[')) last = line;
    at = nl == std::string::npos ? text.size() : nl + 1;
  }
  return tool::parse_json(last);
}

inline double number(const tool::Json& j, const std::string& key) { return std::get<double>(j.object().at(key).value); }
inline std::string text(const tool::Json& j, const std::string& key) { return std::get<std::string>(j.object().at(key).value); }

}  // namespace prime::test
