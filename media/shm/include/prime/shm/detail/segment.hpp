#pragma once

#include <boost/interprocess/mapped_region.hpp>
#include <boost/interprocess/shared_memory_object.hpp>

#include <cctype>
#include <cstddef>
#include <cstdint>
#include <cstdio>
#include <optional>
#include <string>
#include <string_view>

#include "prime/common/fingerprint.hpp"
#include "prime/logic/error.hpp"

namespace prime::shm::detail {

namespace bip = boost::interprocess;

// One named POSIX shared-memory segment, mapped read-write into this process
// for as long as the object lives. Boost.Interprocess creates, sizes, maps and
// removes it; nothing here synchronises: what lives inside does that itself.
class Segment {
 public:
  // Creates `name` with `size` bytes (zero-filled) and `permissions`, or
  // nothing when it exists already.
  static std::optional<Segment> create(const std::string& name, std::size_t size, unsigned permissions) {
    try {
      bip::permissions perm;
      perm.set_permissions(permissions);
      bip::shared_memory_object object{bip::create_only, name.c_str(), bip::read_write, perm};
      object.truncate(static_cast<bip::offset_t>(size));
      return Segment{name, std::move(object)};
    } catch (const bip::interprocess_exception& e) {
      if (e.get_error_code() == bip::already_exists_error) return std::nullopt;
      throw Failure{{Errc::unreachable, "shared memory '" + name + "': cannot create: " + e.what()}};
    }
  }

  // Maps the existing segment `name`, or nothing when there is none (or it
  // is still being sized by its creator).
  static std::optional<Segment> open(const std::string& name) {
    try {
      bip::shared_memory_object object{bip::open_only, name.c_str(), bip::read_write};
      bip::offset_t size = 0;
      if (!object.get_size(size) || size == 0) return std::nullopt;
      return Segment{name, std::move(object)};
    } catch (const bip::interprocess_exception& e) {
      if (e.get_error_code() == bip::not_found_error) return std::nullopt;
      throw Failure{{Errc::unreachable, "shared memory '" + name + "': cannot open: " + e.what()}};
    }
  }

  static void remove(const std::string& name) noexcept { bip::shared_memory_object::remove(name.c_str()); }

  [[nodiscard]] std::byte* data() const noexcept { return static_cast<std::byte*>(region_.get_address()); }
  [[nodiscard]] std::size_t size() const noexcept { return region_.get_size(); }
  [[nodiscard]] const std::string& name() const noexcept { return name_; }

 private:
  Segment(std::string name, bip::shared_memory_object object)
      : name_{std::move(name)}, region_{object, bip::read_write} {}

  std::string name_;
  bip::mapped_region region_;  // the mapping outlives the descriptor, which closes here
};

// The segment name for `what` in `domain`: "prime.<domain>.<what>", with
// anything but [A-Za-z0-9_.-] escaped so topic paths ("lidar/scan") fit, and
// long names shortened with a hash so they stay under NAME_MAX.
inline std::string segment_name(std::string_view domain, std::string_view kind, std::string_view what) {
  std::string name = "prime.";
  auto append = [&name](std::string_view part) {
    for (unsigned char c : part) {
      if (std::isalnum(c) || c == '_' || c == '-' || c == '.') {
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
    std::snprintf(hash, sizeof hash, "#%016llx",
                  static_cast<unsigned long long>(prime::detail::fnv1a(name)));
    name = name.substr(0, 180) + hash;
  }
  return name;
}

}  // namespace prime::shm::detail
