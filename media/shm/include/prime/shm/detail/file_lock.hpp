#pragma once

#include <fcntl.h>

#include <algorithm>
#include <cerrno>
#include <chrono>
#include <string>
#include <thread>

#include "prime/logic/error.hpp"

namespace prime::shm::detail {

// Byte-range locks of open file descriptions (Linux OFD locks). The kernel
// drops them when the last descriptor of their open file description closes,
// which a process's death does, in whatever pid namespace it ran: the
// liveness of a participant, and a registry lock no dead holder can keep.
// Two descriptors opened separately conflict even within one process, so
// each participant (each shm::Core) has its own.

// The byte at `at`, for a lock of `type` (F_WRLCK, F_UNLCK).
inline struct flock one_byte(short type, off_t at) {
  struct flock lock {};
  lock.l_type = type;
  lock.l_whence = SEEK_SET;
  lock.l_start = at;
  lock.l_len = 1;
  return lock;
}

inline bool try_lock_byte(int fd, off_t at) {
  auto lock = one_byte(F_WRLCK, at);
  return ::fcntl(fd, F_OFD_SETLK, &lock) == 0;
}

inline void unlock_byte(int fd, off_t at) {
  auto lock = one_byte(F_UNLCK, at);
  ::fcntl(fd, F_OFD_SETLK, &lock);
}

// Whether another open file description holds the byte at `at`.
[[nodiscard]] inline bool locked_by_other(int fd, off_t at) {
  auto lock = one_byte(F_WRLCK, at);
  if (::fcntl(fd, F_OFD_GETLK, &lock) != 0) return true;  // cannot tell: count it as held
  return lock.l_type != F_UNLCK;
}

// Takes the byte at `at`, waiting for its holder (who holds it for
// microseconds) up to `timeout`; past that, a Failure naming `what`.
inline void lock_byte(int fd, off_t at, const std::string& what,
                      std::chrono::milliseconds timeout = std::chrono::seconds{10}) {
  const auto deadline = std::chrono::steady_clock::now() + timeout;
  auto pause = std::chrono::microseconds{20};
  while (!try_lock_byte(fd, at)) {
    if (errno != EAGAIN && errno != EACCES && errno != EINTR)
      throw Failure{{Errc::unreachable, what + ": cannot lock (" + std::to_string(errno) + ")"}};
    if (std::chrono::steady_clock::now() >= deadline)
      throw Failure{{Errc::timeout, what + ": held by a live participant for more than " +
                                        std::to_string(timeout.count()) + " ms (is one stopped in a debugger?)"}};
    std::this_thread::sleep_for(pause);
    pause = std::min(pause * 2, std::chrono::microseconds{1000});
  }
}

}  // namespace prime::shm::detail
