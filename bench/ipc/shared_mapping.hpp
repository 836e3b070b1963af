#pragma once

#include <sys/mman.h>
#include <unistd.h>

#include <cerrno>
#include <cstddef>
#include <memory>
#include <new>
#include <stdexcept>
#include <system_error>
#include <type_traits>
#include <utility>

#include "unique_fd.hpp"

namespace prime::bench::ipc {

// Memory two processes share: an anonymous memfd mapped MAP_SHARED. The
// creating process hands fd() to its child (ipc::Link passes it on), and the
// child maps the same pages with adopt(). Nothing has a name in /dev/shm, so
// nothing is left behind when a process dies.
class SharedMapping {
 public:
  // A new, zero-filled mapping of `bytes`. The fd is close-on-exec; Link
  // clears that for the fds it passes to a child.
  [[nodiscard]] static SharedMapping create(const char* name, std::size_t bytes) {
    UniqueFd fd{::memfd_create(name, MFD_CLOEXEC)};
    if (!fd) throw std::system_error{errno, std::generic_category(), "memfd_create"};
    if (::ftruncate(fd.get(), static_cast<off_t>(bytes)) != 0)
      throw std::system_error{errno, std::generic_category(), "ftruncate"};
    return SharedMapping{std::move(fd), bytes};
  }

  // Maps a mapping another process created; takes ownership of `fd`.
  [[nodiscard]] static SharedMapping adopt(int fd, std::size_t bytes) { return SharedMapping{UniqueFd{fd}, bytes}; }

  SharedMapping(SharedMapping&& other) noexcept
      : fd_{std::move(other.fd_)}, data_{std::exchange(other.data_, nullptr)}, size_{std::exchange(other.size_, 0)} {}
  SharedMapping& operator=(SharedMapping&& other) noexcept {
    SharedMapping old{std::move(*this)};
    fd_ = std::move(other.fd_);
    data_ = std::exchange(other.data_, nullptr);
    size_ = std::exchange(other.size_, 0);
    return *this;
  }
  SharedMapping(const SharedMapping&) = delete;
  SharedMapping& operator=(const SharedMapping&) = delete;
  ~SharedMapping() {
    if (data_ != nullptr) ::munmap(data_, size_);
  }

  [[nodiscard]] int fd() const noexcept { return fd_.get(); }
  [[nodiscard]] std::size_t size() const noexcept { return size_; }
  [[nodiscard]] void* data() const noexcept { return data_; }

  // The creator starts the lifetime of the one T at the start of the mapping...
  template <class T, class... Args>
  T& construct(Args&&... args) {
    static_assert(std::is_trivially_destructible_v<T>, "a T in shared memory outlives this process's view of it");
    check_fits<T>();
    return *std::construct_at(static_cast<T*>(data_), std::forward<Args>(args)...);
  }

  // ...and the other process uses it.
  template <class T>
  [[nodiscard]] T& as() const {
    check_fits<T>();
    return *std::launder(static_cast<T*>(data_));
  }

 private:
  SharedMapping(UniqueFd fd, std::size_t bytes) : fd_{std::move(fd)}, size_{bytes} {
    void* data = ::mmap(nullptr, bytes, PROT_READ | PROT_WRITE, MAP_SHARED, fd_.get(), 0);
    if (data == MAP_FAILED) throw std::system_error{errno, std::generic_category(), "mmap"};
    data_ = data;
  }

  template <class T>
  void check_fits() const {
    static_assert(alignof(T) <= 4096, "mappings are page aligned");
    if (sizeof(T) > size_) throw std::length_error{"SharedMapping: the type does not fit the mapping"};
  }

  UniqueFd fd_;
  void* data_ = nullptr;
  std::size_t size_ = 0;
};

}  // namespace prime::bench::ipc
