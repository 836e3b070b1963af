#include "support/futex_calls.hpp"

#include <sys/syscall.h>

#include <cstdarg>

namespace {
std::atomic<std::uint64_t> calls{0};
}

extern "C" long __real_syscall(long number, ...);  // libc's, under -Wl,--wrap=syscall

// Every syscall(2) of the objects linked with --wrap=syscall comes here.
// It passes on six arguments whatever the call took, as libc's syscall()
// itself loads six registers: the kernel reads only those its call has.
extern "C" long __wrap_syscall(long number, ...) {
  va_list list;
  va_start(list, number);
  long a[6];
  for (auto& arg : a) arg = va_arg(list, long);
  va_end(list);
  if (number == SYS_futex) calls.fetch_add(1, std::memory_order_relaxed);
  return __real_syscall(number, a[0], a[1], a[2], a[3], a[4], a[5]);
}

std::uint64_t prime::test::futex_calls() noexcept { return calls.load(std::memory_order_relaxed); }
