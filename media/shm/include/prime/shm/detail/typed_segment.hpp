#pragma once

#include <atomic>
#include <cstddef>
#include <new>
#include <optional>
#include <string>
#include <utility>

#include "prime/logic/error.hpp"
#include "prime/shm/detail/registry.hpp"
#include "prime/shm/detail/segment.hpp"

namespace prime::shm::detail {

// What a topic's segment and a service's share: a header that begins with
// a magic number (stored last by its creator, so 0 means "not set up yet")
// and a layout version, and a geometry read once from that header and
// checked against the segment's own size before anything is reached
// through it. `Header` names its kind and numbers (kKind, kMagic, kLayout:
// versions.hpp); `Geometry::of(header)` reads the geometry and
// `damage(header, geometry, size)` says what breaks its bounds.
//
// Errors: Failure with Errc::type_mismatch (made by another version of
// Prime), Errc::damaged (a geometry its segment cannot hold), and those of
// Segment (no_space, not_found, unreachable).
template <class Header, class Geometry>
class TypedSegment {
 public:
  // Opens segment `name` of this kind in `registry`'s domain, making it
  // `bytes` long and calling `set_up(data)` on it when it is new.
  template <class SetUp>
  static TypedSegment open(const Registry& registry, const std::string& name, std::size_t bytes, SetUp&& set_up) {
    auto segment = Segment::open(
        segment_name(registry.domain(), Header::kKind, name), registry.access(), bytes, what(name),
        [&](std::byte* data, std::size_t size) { return is_set_up(name, data, size); },
        [&](std::byte* data, std::size_t) { set_up(data); });
    return TypedSegment{name, std::move(segment)};
  }

  // Segment `name` as it is, or nothing where there is none, where it is
  // not set up yet or where another version of Prime made it: for clients
  // and tools, which make nothing.
  static std::optional<TypedSegment> open_existing(const Registry& registry, const std::string& name) {
    auto segment = Segment::open_existing(segment_name(registry.domain(), Header::kKind, name), registry.access());
    if (!segment || segment->size() < sizeof(Header)) return std::nullopt;
    const auto& header = *at(segment->data());
    if (header.magic.load(std::memory_order_acquire) != Header::kMagic || header.layout != Header::kLayout)
      return std::nullopt;
    return TypedSegment{name, std::move(*segment)};
  }

  [[nodiscard]] Segment& segment() noexcept { return segment_; }
  [[nodiscard]] const Segment& segment() const noexcept { return segment_; }
  [[nodiscard]] std::byte* data() const noexcept { return segment_.data(); }
  [[nodiscard]] Header& header() const noexcept { return *header_; }
  [[nodiscard]] const Geometry& geometry() const noexcept { return geometry_; }

  // "topic 'name'", "service 'name'": how errors name it.
  static std::string what(const std::string& name) { return std::string{Header::kKind} + " '" + name + "'"; }

 private:
  TypedSegment(const std::string& name, Segment segment)
      : segment_{std::move(segment)}, header_{at(segment_.data())}, geometry_{checked(name, *header_, segment_.size())} {}

  static Header* at(std::byte* data) noexcept { return std::launder(reinterpret_cast<Header*>(data)); }

  static bool is_set_up(const std::string& name, std::byte* data, std::size_t size) {
    if (size < sizeof(Header)) return false;
    const auto& header = *at(data);
    const auto magic = header.magic.load(std::memory_order_acquire);
    if (magic == 0) return false;  // new, or its creator died setting it up
    if (magic != Header::kMagic || header.layout != Header::kLayout)
      throw Failure{{Errc::type_mismatch, what(name) + ": made by another version of Prime (layout " +
                                              std::to_string(header.layout) + ", this one reads " +
                                              std::to_string(Header::kLayout) + ")"}};
    return true;  // its geometry is checked when it is mapped
  }

  // The geometry `header` records, read once and checked against the segment.
  static Geometry checked(const std::string& name, const Header& header, std::size_t size) {
    const auto geometry = Geometry::of(header);
    if (const auto broken = damage(header, geometry, size); !broken.empty())
      throw Failure{{Errc::damaged, what(name) + ": its shared memory is damaged (" + broken + ")"}};
    return geometry;
  }

  Segment segment_;
  Header* header_;
  Geometry geometry_;  // read once from the header, and checked
};

}  // namespace prime::shm::detail
