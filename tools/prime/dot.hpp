#pragma once

#include <initializer_list>
#include <string>
#include <string_view>

#include "json.hpp"

namespace prime::tool {

// A Graphviz label of several lines: each escaped as a JSON string is (DOT
// reads the same escapes for quotes and backslashes), joined by DOT's line
// break, \n, which quoting the whole would escape into the text "\n".
inline std::string dot_label(std::initializer_list<std::string_view> lines) {
  std::string out = "\"";
  bool first = true;
  for (const auto line : lines) {
    if (!first) out += "\\n";
    first = false;
    const auto quoted = quote(line);
    out.append(quoted, 1, quoted.size() - 2);
  }
  return out + "\"";
}

}  // namespace prime::tool
