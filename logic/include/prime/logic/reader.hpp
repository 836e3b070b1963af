#pragma once

#include <concepts>
#include <cstdint>
#include <expected>
#include <memory>
#include <optional>
#include <stop_token>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/sample.hpp"

namespace prime {

// One subscriber's view of a source: it has its own cursor, so it sees every
// value published after it subscribed (less what a full buffer dropped, which
// `lost()` counts). Each medium provides the Impl.
//
// Not thread-safe: one thread at a time uses a Reader.
template <class T>
class Reader {
 public:
  class Impl {
   public:
    virtual ~Impl() = default;
    virtual std::optional<Sample<T>> try_read() = 0;
    virtual std::expected<Sample<T>, Error> read_until(Clock::time_point deadline,
                                                       std::stop_token stop) = 0;
    [[nodiscard]] virtual std::uint64_t lost() const = 0;

    // Waits like read_until for one value, then takes up to `max` in all.
    // Media override it to take a batch at once.
    virtual std::expected<std::size_t, Error> read_some(std::vector<Sample<T>>& out, std::size_t max,
                                                        Clock::time_point deadline, std::stop_token stop) {
      auto first = read_until(deadline, std::move(stop));
      if (!first) return std::unexpected(std::move(first.error()));
      out.push_back(std::move(*first));
      std::size_t n = 1;
      for (; n < max; ++n) {
        auto next = try_read();
        if (!next) break;
        out.push_back(std::move(*next));
      }
      return n;
    }

    // Moves `latest` on to the newest unread value, if there is one. Media
    // whose values pin memory override it to let go of the old value first
    // and to skip straight to the newest.
    virtual void read_latest(std::optional<Sample<T>>& latest) {
      while (auto s = try_read()) latest = std::move(s);
    }
  };

  explicit Reader(std::unique_ptr<Impl> impl) : impl_{std::move(impl)} {}

  // The next unread value, without waiting.
  [[nodiscard]] std::optional<Sample<T>> try_read() { return impl_->try_read(); }

  // Every unread value, oldest first, without waiting.
  [[nodiscard]] std::vector<Sample<T>> read_all() {
    std::vector<Sample<T>> all;
    while (auto s = impl_->try_read()) all.push_back(std::move(*s));
    return all;
  }

  // The next unread value, waiting until `deadline` (Errc::timeout) or until
  // `stop` is requested (Errc::stopped).
  [[nodiscard]] std::expected<Sample<T>, Error> read_until(Clock::time_point deadline,
                                                           std::stop_token stop = {}) {
    return impl_->read_until(deadline, std::move(stop));
  }
  template <class Rep, class Period>
  [[nodiscard]] std::expected<Sample<T>, Error> read_for(std::chrono::duration<Rep, Period> timeout,
                                                         std::stop_token stop = {}) {
    return read_until(deadline_after(timeout), std::move(stop));
  }

  // Appends to `out` what is unread, at most `max` values, after waiting as
  // read_until does for the first: how a worker drains a busy source with one
  // wake-up for many values. A `max` of 0 asks for nothing: 0 at once.
  std::expected<std::size_t, Error> read_some(std::vector<Sample<T>>& out, std::size_t max,
                                              Clock::time_point deadline, std::stop_token stop = {}) {
    if (max == 0) return 0;
    return impl_->read_some(out, max, deadline, std::move(stop));
  }

  // The newest value: skips to the end of what is unread and remembers it, so
  // asking again before anything new arrives gives the same value.
  [[nodiscard]] std::optional<Sample<T>> latest()
    requires std::copy_constructible<T>
  {
    impl_->read_latest(last_);
    return last_;
  }

  // How many values this reader missed because its buffer was full.
  [[nodiscard]] std::uint64_t lost() const { return impl_->lost(); }

 private:
  std::unique_ptr<Impl> impl_;
  std::optional<Sample<T>> last_;
};

}  // namespace prime
