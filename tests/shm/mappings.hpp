#pragma once

#include <cstdint>
#include <cstdio>
#include <fstream>
#include <string>
#include <utility>

namespace prime::test {

// The address range of this process's mapping of a /dev/shm file whose
// name contains `part`, from /proc/self/maps; {0, 0} when there is none.
inline std::pair<std::uintptr_t, std::uintptr_t> mapping_of(const std::string& part) {
  std::ifstream maps{"/proc/self/maps"};
  std::string line;
  while (std::getline(maps, line)) {
    if (line.find("/dev/shm/") == std::string::npos || line.find(part) == std::string::npos) continue;
    std::uintptr_t begin = 0, end = 0;
    std::sscanf(line.c_str(), "%lx-%lx", &begin, &end);
    return {begin, end};
  }
  return {0, 0};
}

// Whether `p` lies in one of this process's mappings of a /dev/shm file
// whose name contains `part` (a file may be mapped more than once).
inline bool inside_mapping_of(const std::string& part, const void* p) {
  std::ifstream maps{"/proc/self/maps"};
  std::string line;
  const auto at = reinterpret_cast<std::uintptr_t>(p);
  while (std::getline(maps, line)) {
    if (line.find("/dev/shm/") == std::string::npos || line.find(part) == std::string::npos) continue;
    std::uintptr_t begin = 0, end = 0;
    std::sscanf(line.c_str(), "%lx-%lx", &begin, &end);
    if (at >= begin && at < end) return true;
  }
  return false;
}

}  // namespace prime::test
