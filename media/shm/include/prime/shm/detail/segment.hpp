#pragma once

#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/statvfs.h>

#include <boost/interprocess/mapped_region.hpp>
#include <boost/interprocess/shared_memory_object.hpp>

#include <cctype>
#include <cerrno>
#include <charconv>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <cstring>
#include <fcntl.h>
#include <limits>
#include <optional>
#include <string>
#include <string_view>
#include <unistd.h>

#include "prime/common/fingerprint.hpp"
#include "prime/logic/error.hpp"
#include "prime/shm/detail/file_lock.hpp"

namespace prime::shm::detail {

namespace bip = boost::interprocess;

inline constexpr const char* kShmDirectory = "/dev/shm";

// Bytes free for shared memory on this machine (in this mount namespace).
[[nodiscard]] inline std::uint64_t shm_bytes_free() {
  struct statvfs fs {};
  if (::statvfs(kShmDirectory, &fs) != 0) return 0;
  return static_cast<std::uint64_t>(fs.f_bavail) * fs.f_frsize;
}

// Whose segments a participant accepts, and what its own may allow: a
// segment is taken only from `owner`, with no permission bit beyond
// `permissions`. Another user of the machine who made a domain's files
// first (before its participants came) would otherwise have them set up
// and used in files that user maps read-write.
struct Access {
  unsigned permissions = 0600;
  uid_t owner = ::geteuid();
};

// What is wrong with the file open at `fd` for `access`
// (empty when nothing is): it must be a regular file of the owner, with no
// permission bit beyond those asked for. `mode_too`: false for one opened
// only to look at, whose asked-for mode is not known.
inline std::string untrusted(int fd, const Access& access, bool mode_too = true) {
  struct stat st {};
  if (::fstat(fd, &st) != 0) return "cannot stat it (" + std::string{std::strerror(errno)} + ")";
  char mode[16];
  std::snprintf(mode, sizeof mode, "%04o", static_cast<unsigned>(st.st_mode & 07777));
  if (!S_ISREG(st.st_mode)) return "it is not a regular file";
  if (st.st_uid != access.owner)
    return "it belongs to uid " + std::to_string(st.st_uid) + ", not to uid " + std::to_string(access.owner) +
           " (the owner this participant accepts: DomainOptions::owner)";
  if (mode_too && (st.st_mode & 07777 & ~access.permissions) != 0) {
    char asked[16];
    std::snprintf(asked, sizeof asked, "%04o", access.permissions);
    return std::string{"its mode "} + mode + " allows more than the " + asked + " asked for (DomainOptions::permissions)";
  }
  return {};
}

// One named POSIX shared-memory segment, mapped read-write into this process
// for as long as the object lives, with its descriptor kept open (the
// registry's liveness locks live on it). Boost.Interprocess opens, maps and
// removes it; nothing here synchronises what lives inside.
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
      Segment segment{name, open_object(name, access, what)};
      segment.check(access, what, true);
      lock_byte(segment.fd(), 0, what + " (being set up)");
      struct Unlock {
        int fd;
        ~Unlock() { unlock_byte(fd, 0); }
      } unlock{segment.fd()};
      if (!segment.linked()) continue;  // removed while we waited: open what replaced it
      if (segment.file_size() > 0) {
        segment.map();
        if (is_ready(segment.data(), segment.size())) return segment;
      }
      segment.reserve(size, what);
      segment.map();
      set_up(segment.data(), segment.size());
      return segment;
    }
  }

  // Maps the existing segment `name`, or nothing when there is none (or it
  // is still empty). For inspection: it takes no lock. One not made as
  // `access` allows is refused (Errc::unreachable); with no access given,
  // only its owner is checked (this process's effective user).
  static std::optional<Segment> open_existing(const std::string& name, const std::optional<Access>& access = {}) {
    try {
      Segment segment{name, bip::shared_memory_object{bip::open_only, name.c_str(), bip::read_write}};
      segment.check(access.value_or(Access{}), "shared memory '" + name + "'", access.has_value());
      if (segment.file_size() == 0) return std::nullopt;
      segment.map();
      return segment;
    } catch (const bip::interprocess_exception& e) {
      if (e.get_error_code() == bip::not_found_error) return std::nullopt;
      throw Failure{{Errc::unreachable, "shared memory '" + name + "': cannot open: " + e.what()}};
    }
  }

  // Removes the segment `name`; 0, or why not (an errno: only its owner may
  // remove a file of /dev/shm). One already gone counts as removed.
  static int remove(const std::string& name) noexcept {
    return ::shm_unlink(name.c_str()) == 0 || errno == ENOENT ? 0 : errno;
  }

  // Removes this segment's name, if it still leads here, holding the
  // segment's set-up lock: several openers that found it outdated remove it
  // once, and none removes what another made in its place meanwhile.
  void remove_name(const std::string& what) {
    lock_byte(fd(), 0, what + " (being replaced)");
    struct Unlock {
      int fd;
      ~Unlock() { unlock_byte(fd, 0); }
    } unlock{fd()};
    if (linked()) remove(name_);
  }

  [[nodiscard]] std::byte* data() const noexcept { return static_cast<std::byte*>(region_.get_address()); }
  [[nodiscard]] std::size_t size() const noexcept { return region_.get_size(); }
  [[nodiscard]] const std::string& name() const noexcept { return name_; }
  [[nodiscard]] int fd() const noexcept { return object_.get_mapping_handle().handle; }

  // Whether the name still leads to this segment.
  [[nodiscard]] bool linked() const {
    struct stat mine {}, named {};
    const auto path = std::string{kShmDirectory} + "/" + name_;
    return ::fstat(fd(), &mine) == 0 && ::stat(path.c_str(), &named) == 0 && mine.st_ino == named.st_ino &&
           mine.st_dev == named.st_dev;
  }

 private:
  Segment(std::string name, bip::shared_memory_object object) : name_{std::move(name)}, object_{std::move(object)} {}

  // Opens `name`, creating it when missing, unless the segments `access`
  // admits are another user's: what this process made would be its own,
  // and refused. Those it only opens, and a missing one is Errc::not_found.
  static bip::shared_memory_object open_object(const std::string& name, const Access& access, const std::string& what) {
    try {
      if (access.owner != ::geteuid()) return bip::shared_memory_object{bip::open_only, name.c_str(), bip::read_write};
      bip::permissions perm;
      perm.set_permissions(access.permissions);
      return bip::shared_memory_object{bip::open_or_create, name.c_str(), bip::read_write, perm};
    } catch (const bip::interprocess_exception& e) {
      if (e.get_error_code() == bip::not_found_error)
        throw Failure{{Errc::not_found, what + ": " + kShmDirectory + "/" + name + " is not there, and only uid " +
                                            std::to_string(access.owner) +
                                            " (DomainOptions::owner) makes this domain's segments: it is joined, not made, here"}};
      throw Failure{{Errc::unreachable, what + ": cannot open shared memory '" + name + "': " + e.what()}};
    }
  }

  void check(const Access& access, const std::string& what, bool mode_too) const {
    if (const auto why = untrusted(fd(), access, mode_too); !why.empty())
      throw Failure{{Errc::unreachable, what + ": refused " + kShmDirectory + "/" + name_ + ": " + why}};
  }

  [[nodiscard]] std::size_t file_size() const {
    struct stat st {};
    return ::fstat(fd(), &st) == 0 ? static_cast<std::size_t>(st.st_size) : 0;
  }

  // Grows the file to `size` and reserves its blocks; never shrinks it: a
  // segment whose header reads as not set up (its creator died half-way,
  // or another program zeroed it) may be mapped by live participants, and
  // cutting pages out from under them would kill each with SIGBUS.
  void reserve(std::size_t size, const std::string& what) {
    region_ = bip::mapped_region{};
    const auto free = shm_bytes_free() + file_size();  // what it has already counts as free to it
    const int error = size > static_cast<std::size_t>(std::numeric_limits<off_t>::max())
                          ? EFBIG
                          : ::posix_fallocate(fd(), 0, static_cast<off_t>(size));  // grows it, never shrinks
    if (error == 0) return;
    remove(name_);  // nobody uses a segment that was never set up
    const bool full = error == ENOSPC || error == EFBIG || error == ENOMEM;
    throw Failure{{full ? Errc::no_space : Errc::unreachable,
                   what + ": needs " + std::to_string(size) + " bytes of shared memory, but " + kShmDirectory +
                       " has " + std::to_string(free) + " bytes free (" + std::strerror(error) + ")"}};
  }

  void map() { region_ = bip::mapped_region{object_, bip::read_write}; }

  std::string name_;
  bip::shared_memory_object object_;
  bip::mapped_region region_;
};

// The text segment_name() escaped. A '%' not followed by two hex digits
// (a name segment_name() never made) stays as it is.
inline std::string unescape(std::string_view text) {
  std::string out;
  auto hex = [&](std::size_t at, unsigned& value) {  // the two hex digits at `at`
    const auto [end, error] = std::from_chars(text.data() + at, text.data() + at + 2, value, 16);
    return error == std::errc{} && end == text.data() + at + 2;
  };
  for (std::size_t i = 0; i < text.size(); ++i) {
    unsigned value = 0;
    if (text[i] == '%' && i + 2 < text.size() && hex(i + 1, value)) {
      out.push_back(static_cast<char>(value));
      i += 2;
    } else {
      out.push_back(text[i]);
    }
  }
  return out;
}

// The segment name for `what` in `domain`: "prime.<domain>.<kind>.<what>",
// with anything but [A-Za-z0-9_-] escaped (so "." only separates, and domain
// "a.b" with topic "c" never meets domain "a" with topic "b.c"), and long
// names shortened with a hash so they stay under NAME_MAX.
inline std::string segment_name(std::string_view domain, std::string_view kind, std::string_view what) {
  std::string name = "prime.";
  auto append = [&name](std::string_view part) {
    for (unsigned char c : part) {
      if (std::isalnum(c) || c == '_' || c == '-') {
        name.push_back(static_cast<char>(c));
      } else {
        char hex[4];
        std::snprintf(hex, sizeof hex, "%%%02X", c);
        name.append(hex);
      }
    }
  };
  append(domain);
  name.push_back('.');
  name.append(kind);
  name.push_back('.');
  append(what);
  if (name.size() > 200) {
    char hash[20];
    std::snprintf(hash, sizeof hash, "#%016llx", static_cast<unsigned long long>(prime::detail::fnv1a(name)));
    name = name.substr(0, 180) + hash;
  }
  return name;
}

}  // namespace prime::shm::detail
