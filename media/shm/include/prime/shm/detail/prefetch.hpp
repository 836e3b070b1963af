#pragma once

namespace prime::shm::detail {

// Where the CPU can fetch a line for writing (PREFETCHW: x86 since
// Broadwell, every 64-bit AMD), a line another CPU last wrote arrives ready
// for a read-modify-write, instead of shared first and then taken again.
#if defined(__x86_64__)
inline const bool kCanPrefetchForWrite = [] {
  __builtin_cpu_init();
  return __builtin_cpu_supports("prfchw") != 0;
}();
#endif

// Starts fetching the line at `p` for writing; a hint, never a fault.
inline void prefetch_for_write(const void* p) noexcept {
#if defined(__x86_64__)
  if (kCanPrefetchForWrite) {
    asm volatile("prefetchw %0" : : "m"(*static_cast<const char*>(p)));
    return;
  }
#endif
  __builtin_prefetch(p, 1);
}

}  // namespace prime::shm::detail
