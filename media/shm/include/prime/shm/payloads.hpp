#pragma once

#include <cstddef>
#include <cstdint>

namespace prime::shm::detail {

// Where a topic's payloads lie in this process: chunk i's at
// first + i × stride. Loans, batches and views copy it, so they find a
// sample's bytes without a call or a walk through their owner.
struct Payloads {
  std::byte* first = nullptr;
  std::uint64_t stride = 0;
  [[nodiscard]] std::byte* operator[](std::uint32_t chunk) const noexcept { return first + chunk * stride; }
};

}  // namespace prime::shm::detail
