#pragma once

#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <string>
#include <string_view>
#include <system_error>

#include "unique_fd.hpp"

namespace prime::bench::ipc {

// A file in memory only (a memfd), for RouDi's config and its output, so
// that a run leaves no file behind however it ends. A child that inherits
// fd() opens it as path().
class MemoryFile {
 public:
  explicit MemoryFile(const char* name) : fd_{::memfd_create(name, MFD_CLOEXEC)} {
    if (!fd_) throw std::system_error{errno, std::generic_category(), "memfd_create"};
  }

  [[nodiscard]] int fd() const noexcept { return fd_.get(); }
  [[nodiscard]] std::string path() const { return "/proc/self/fd/" + std::to_string(fd_.get()); }

  void write(std::string_view text) {
    while (!text.empty()) {
      const ssize_t n = ::write(fd_.get(), text.data(), text.size());
      if (n < 0 && errno != EINTR) throw std::system_error{errno, std::generic_category(), "write"};
      if (n > 0) text.remove_prefix(static_cast<std::size_t>(n));
    }
  }

  [[nodiscard]] std::string read() const {
    std::string text;
    char chunk[4096];
    for (ssize_t n; (n = ::pread(fd_.get(), chunk, sizeof chunk, static_cast<off_t>(text.size()))) > 0;)
      text.append(chunk, static_cast<std::size_t>(n));
    return text;
  }

 private:
  UniqueFd fd_;
};

}  // namespace prime::bench::ipc
