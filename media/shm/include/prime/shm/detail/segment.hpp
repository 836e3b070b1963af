#pragma once

#include <sys/types.h>
#include <unistd.h>

#include <cstddef>
#include <cstdint>
#include <memory>
#include <optional>
#include <string>
#include <string_view>

#include "prime/logic/error.hpp"
#include "prime/shm/detail/file_lock.hpp"

namespace prime::shm::detail {

inline constexpr const char* kShmDirectory = "/dev/shm";

// Bytes free for shared memory on this machine (in this mount namespace).
[[nodiscard]] std::uint64_t shm_bytes_free();

// Whose segments a participant accepts, and what its own may allow: a
// segment is taken only from `owner`, with no permission bit beyond
// `permissions`. Another user of the machine who made a domain's files
// first (before its participants came) would otherwise have them set up
// and used in files that user maps read-write.
//
// And how segments are mapped: with `prefault`, every page of a segment is
// mapped in as it is opened, so that no later access to it takes a page
// fault (the first publish into a chunk, say).
struct Access {
  unsigned permissions = 0600;
  uid_t owner = ::geteuid();
  bool prefault = false;
};

// What is wrong with the file open at `fd` for `access`
// (empty when nothing is): it must be a regular file of the owner, with no
// permission bit beyond those asked for. `mode_too`: false for one opened
// only to look at, whose asked-for mode is not known.
std::string untrusted(int fd, const Access& access, bool mode_too = true);

// One named POSIX shared-memory segment, mapped read-write into this process
// for as long as the object lives, with its descriptor kept open (the
// registry's liveness locks live on it). Boost.Interprocess opens, maps and
// removes it, in the compiled library (segment.cpp): no user translation
// unit sees Boost. Nothing here synchronises what lives inside.
class Segment {
 public:
  // Opens `name`, creating it when missing. The opener holds the segment's
  // set-up lock (a lock on its byte 0, dropped by the kernel if the holder
  // dies) while it looks: when `is_ready(data, size)` says the contents are
  // not set up (it is new, or its creator died half-way), this opener sizes
  // it to at least `size` (never smaller: others may map it), reserving
  // every byte now (posix_fallocate: a full /dev/shm is an error here,
  // never a SIGBUS later), and calls `set_up(data, size)`. A segment not
  // made as `access` allows is refused (Errc::unreachable). Errors name
  // `what`.
  template <class IsReady, class SetUp>
  static Segment open(const std::string& name, const Access& access, std::size_t size, const std::string& what,
                      IsReady&& is_ready, SetUp&& set_up) {
    while (true) {
      auto segment = open_object(name, access, what);
      segment.check(access, what, true);
      lock_byte(segment.fd(), 0, what + " (being set up)");
      struct Unlock {
        int fd;
        ~Unlock() { unlock_byte(fd, 0); }
      } unlock{segment.fd()};
      if (!segment.linked()) continue;  // removed while we waited: open what replaced it
      if (segment.file_size() > 0) {
        segment.map(access.prefault);
        if (is_ready(segment.data(), segment.size())) return segment;
      }
      segment.reserve(size, what);
      segment.map(access.prefault);
      set_up(segment.data(), segment.size());
      return segment;
    }
  }

  // Maps the existing segment `name`, or nothing when there is none (or it
  // is still empty). For inspection: it takes no lock. One not made as
  // `access` allows is refused (Errc::unreachable); with no access given,
  // only its owner is checked (this process's effective user).
  static std::optional<Segment> open_existing(const std::string& name, const std::optional<Access>& access = {});

  // Removes the segment `name`; 0, or why not (an errno: only its owner may
  // remove a file of /dev/shm). One already gone counts as removed.
  static int remove(const std::string& name) noexcept;

  // Removes this segment's name, if it still leads here, holding the
  // segment's set-up lock: several openers that found it outdated remove it
  // once, and none removes what another made in its place meanwhile.
  void remove_name(const std::string& what);

  Segment(Segment&&) noexcept;
  Segment& operator=(Segment&&) noexcept;
  ~Segment();

  [[nodiscard]] std::byte* data() const noexcept { return data_; }
  [[nodiscard]] std::size_t size() const noexcept { return size_; }
  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  [[nodiscard]] int fd() const noexcept { return fd_; }

  // Whether the name still leads to this segment.
  [[nodiscard]] bool linked() const;

 private:
  struct Mapping;  // Boost.Interprocess's object and region (segment.cpp)
  explicit Segment(std::string name, std::unique_ptr<Mapping> mapping);

  // Opens `name`, creating it when missing, unless the segments `access`
  // admits are another user's: what this process made would be its own,
  // and refused. Those it only opens, and a missing one is Errc::not_found.
  static Segment open_object(const std::string& name, const Access& access, const std::string& what);
  void check(const Access& access, const std::string& what, bool mode_too) const;
  [[nodiscard]] std::size_t file_size() const;
  // Grows the file to `size` and reserves its blocks; never shrinks it: a
  // segment whose header reads as not set up (its creator died half-way,
  // or another program zeroed it) may be mapped by live participants, and
  // cutting pages out from under them would kill each with SIGBUS.
  void reserve(std::size_t size, const std::string& what);
  // Maps the segment read-write; with `prefault`, each of its pages in.
  void map(bool prefault);

  std::string name_;
  std::unique_ptr<Mapping> mapping_;
  int fd_ = -1;
  std::byte* data_ = nullptr;  // the mapping's, read in place
  std::size_t size_ = 0;
};

// The text segment_name() escaped. A '%' not followed by two hex digits
// (a name segment_name() never made) stays as it is.
std::string unescape(std::string_view text);

// The segment name for `what` in `domain`: "prime.<domain>.<kind>.<what>",
// with anything but [A-Za-z0-9_-] escaped (so "." only separates, and domain
// "a.b" with topic "c" never meets domain "a" with topic "b.c"), and long
// names shortened with a hash so they stay under NAME_MAX.
std::string segment_name(std::string_view domain, std::string_view kind, std::string_view what);

}  // namespace prime::shm::detail
