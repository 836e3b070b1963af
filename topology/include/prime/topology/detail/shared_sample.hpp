#pragma once

#include <atomic>
#include <cstddef>
#include <memory>
#include <utility>

#include "prime/logic/sample.hpp"

namespace prime::detail {

// One published value handed to several readers without copying it at
// publish time: every reader's queue holds a SharedSample of the same value,
// and each reader takes it when it reads. A reader that is the last one still
// holding the value gets it moved; the others copy it then, on their own
// thread. So the publisher never copies, a reader that drops the value
// unread costs no copy, and readers that read one after the other make one
// copy fewer than there are readers (two reading at the same moment may both
// copy: neither can know the other is done with it).
//
// A SharedSample is one reader's claim: dropping it untaken (a queue that
// drops its oldest value, a closed queue, a push that timed out) gives the
// claim up, so the readers left can still move the value.
template <class T>
class SharedSample {
 public:
  // The first of `readers` claims on `sample`. Make the other `readers - 1`
  // with `claim`, and hand one to each reader.
  [[nodiscard]] static SharedSample share(Sample<T>&& sample, std::size_t readers) {
    return SharedSample{new Box{std::move(sample), readers}};
  }
  [[nodiscard]] SharedSample claim() const noexcept { return SharedSample{box_}; }

  SharedSample(SharedSample&& other) noexcept : box_{std::exchange(other.box_, nullptr)} {}
  SharedSample& operator=(SharedSample&& other) noexcept {
    std::swap(box_, other.box_);
    return *this;
  }
  SharedSample(const SharedSample&) = delete;
  SharedSample& operator=(const SharedSample&) = delete;
  ~SharedSample() { release(box_); }

  // The value: moved if no other claim is left, else a copy. Consumes the claim.
  [[nodiscard]] Sample<T> take() && {
    Box* box = std::exchange(box_, nullptr);
    // Acquire: the other readers' copies (made before they gave their claim
    // up) are done before this reader moves the value away.
    if (box->claims.load(std::memory_order_acquire) == 1) {
      const std::unique_ptr<Box> last{box};
      return std::move(last->sample);
    }
    struct Release {
      Box* box;
      ~Release() { release(box); }
    } const after_copy{box};
    return box->sample;
  }

 private:
  struct Box {
    Sample<T> sample;
    std::atomic<std::size_t> claims;
  };

  explicit SharedSample(Box* box) noexcept : box_{box} {}

  static void release(Box* box) noexcept {
    if (box != nullptr && box->claims.fetch_sub(1, std::memory_order_acq_rel) == 1) delete box;
  }

  Box* box_;
};

}  // namespace prime::detail
