// Shared-memory segments: opened, sized, mapped and removed with
// Boost.Interprocess, which stays inside this library.
#include "prime/shm/detail/segment.hpp"

#include <fcntl.h>
#include <sys/mman.h>
#include <sys/stat.h>
#include <sys/statvfs.h>

#include <boost/interprocess/mapped_region.hpp>
#include <boost/interprocess/shared_memory_object.hpp>

#include <cctype>
#include <cerrno>
#include <charconv>
#include <cstdio>
#include <cstring>
#include <limits>
#include <utility>

#include "prime/common/fingerprint.hpp"
#include "prime/logic/error.hpp"

namespace prime::shm::detail {

namespace bip = boost::interprocess;

struct Segment::Mapping {
  bip::shared_memory_object object;
  bip::mapped_region region;
};

std::uint64_t shm_bytes_free() {
  struct statvfs fs {};
  if (::statvfs(kShmDirectory, &fs) != 0) return 0;
  return static_cast<std::uint64_t>(fs.f_bavail) * fs.f_frsize;
}

std::string untrusted(int fd, const Access& access, bool mode_too) {
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

Segment::Segment(std::string name, std::unique_ptr<Mapping> mapping)
    : name_{std::move(name)}, mapping_{std::move(mapping)}, fd_{mapping_->object.get_mapping_handle().handle} {}
Segment::Segment(Segment&&) noexcept = default;
Segment& Segment::operator=(Segment&&) noexcept = default;
Segment::~Segment() = default;

std::optional<Segment> Segment::open_existing(const std::string& name, const std::optional<Access>& access) {
  try {
    Segment segment{name, std::make_unique<Mapping>(
                              Mapping{bip::shared_memory_object{bip::open_only, name.c_str(), bip::read_write}, {}})};
    segment.check(access.value_or(Access{}), "shared memory '" + name + "'", access.has_value());
    if (segment.file_size() == 0) return std::nullopt;
    segment.map(access && access->prefault);
    return segment;
  } catch (const bip::interprocess_exception& e) {
    if (e.get_error_code() == bip::not_found_error) return std::nullopt;
    throw Failure{{Errc::unreachable, "shared memory '" + name + "': cannot open: " + e.what()}};
  }
}

int Segment::remove(const std::string& name) noexcept {
  return ::shm_unlink(name.c_str()) == 0 || errno == ENOENT ? 0 : errno;
}

void Segment::remove_name(const std::string& what) {
  lock_byte(fd(), 0, what + " (being replaced)");
  struct Unlock {
    int fd;
    ~Unlock() { unlock_byte(fd, 0); }
  } unlock{fd()};
  if (linked()) remove(name_);
}

bool Segment::linked() const {
  struct stat mine {}, named {};
  const auto path = std::string{kShmDirectory} + "/" + name_;
  return ::fstat(fd(), &mine) == 0 && ::stat(path.c_str(), &named) == 0 && mine.st_ino == named.st_ino &&
         mine.st_dev == named.st_dev;
}

Segment Segment::open_object(const std::string& name, const Access& access, const std::string& what) {
  auto opened = [&]() -> bip::shared_memory_object {
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
  };
  return Segment{name, std::make_unique<Mapping>(Mapping{opened(), {}})};
}

void Segment::check(const Access& access, const std::string& what, bool mode_too) const {
  if (const auto why = untrusted(fd(), access, mode_too); !why.empty())
    throw Failure{{Errc::unreachable, what + ": refused " + kShmDirectory + "/" + name_ + ": " + why}};
}

std::size_t Segment::file_size() const {
  struct stat st {};
  return ::fstat(fd(), &st) == 0 ? static_cast<std::size_t>(st.st_size) : 0;
}

void Segment::reserve(std::size_t size, const std::string& what) {
  mapping_->region = bip::mapped_region{};
  data_ = nullptr;
  size_ = 0;
  const auto free = shm_bytes_free() + file_size();  // what it has already counts as free to it
  const int error = size > static_cast<std::size_t>(std::numeric_limits<off_t>::max())
                        ? EFBIG
                        : ::posix_fallocate(fd(), 0, static_cast<off_t>(size));  // grows it, never shrinks
  if (error == 0) return;
  remove(name_);  // nobody uses a segment that was never set up
  const bool full = error == ENOSPC || error == EFBIG || error == ENOMEM;
  throw Failure{{full ? Errc::no_space : Errc::unreachable,
                 what + ": needs " + std::to_string(size) + " bytes of shared memory, but " + kShmDirectory + " has " +
                     std::to_string(free) + " bytes free (" + std::strerror(error) + ")"}};
}

void Segment::map(bool prefault) {
  mapping_->region = bip::mapped_region{mapping_->object, bip::read_write};
  data_ = static_cast<std::byte*>(mapping_->region.get_address());
  size_ = mapping_->region.get_size();
  if (!prefault || size_ == 0) return;
  // Linux 5.14 and later map every page in writable, changing no byte.
  if (::madvise(data_, size_, MADV_POPULATE_WRITE) == 0) return;
  // Before that, a read of each page maps it in: tmpfs maps a page of a
  // shared writable mapping writable on a read (it tracks no dirty pages).
  const auto page = static_cast<std::size_t>(::sysconf(_SC_PAGESIZE));
  for (std::size_t at = 0; at < size_; at += page) (void)*reinterpret_cast<volatile const std::byte*>(data_ + at);
}

std::string unescape(std::string_view text) {
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

std::string segment_name(std::string_view domain, std::string_view kind, std::string_view what) {
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
