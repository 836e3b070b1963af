// After setup, the hot paths allocate nothing and take no page fault (issue
// 44 item 5): Shm loan, publish, read and release, one at a time and in
// batches; Shm service calls and the worker that serves them; sync
// matching; the collector; the periodic tick; a Radiant or Liberty chain
// step over trivially copyable values.
//
// How it is counted: this binary replaces the global operator new (every
// form) and, without a sanitizer, interposes malloc and its kin (calling
// glibc's __libc_malloc and friends); each counts per thread and for the
// whole process. Minor page faults come from getrusage: RUSAGE_THREAD for
// the thread that measures, RUSAGE_SELF for all threads. Each path is set
// up, warmed up (2,000 iterations: every ring, chunk pool and cell array on
// these paths, at most 130 entries, goes round many times, so every page
// it uses has been touched), then measured over 100,000 iterations: on the
// measuring thread, on all threads (a path's workers are the only other
// threads of the process then) and, where a worker runs user code (a
// served block, a loop's chain), on that worker's own thread too. Each
// count must be 0.
//
// Under ASan and TSan (GCC's __SANITIZE_ADDRESS__ / __SANITIZE_THREAD__)
// the sanitizer's runtime owns malloc, so it is not interposed, and it
// maps shadow memory as the program touches memory, so minor faults are
// not asserted: only operator new is counted there (the skipped self-checks
// say so in the output).
#include <gtest/gtest.h>

#include <sys/mman.h>
#include <sys/prctl.h>
#include <sys/resource.h>
#include <unistd.h>

#include <atomic>
#include <bit>
#include <cerrno>
#include <charconv>
#include <chrono>
#include <condition_variable>
#include <cstddef>
#include <cstdint>
#include <cstdlib>
#include <fstream>
#include <mutex>
#include <new>
#include <optional>
#include <sstream>
#include <string>
#include <vector>

#include "prime/liberty.hpp"
#include "prime/radiant.hpp"
#include "prime/shm.hpp"
#include "shm/domain.hpp"

#if defined(__SANITIZE_ADDRESS__) || defined(__SANITIZE_THREAD__)
#define PRIME_HOT_PATH_SANITIZED 1
#else
#define PRIME_HOT_PATH_SANITIZED 0
#endif

namespace {

constexpr bool kSanitized = PRIME_HOT_PATH_SANITIZED != 0;

// Made by the calling thread, ever; and by every thread of the process.
thread_local std::uint64_t thread_news = 0;
thread_local std::uint64_t thread_mallocs = 0;
std::atomic<std::uint64_t> process_news{0};
std::atomic<std::uint64_t> process_mallocs{0};

void count_new() noexcept {
  ++thread_news;
  process_news.fetch_add(1, std::memory_order_relaxed);
}

void* counted_new(std::size_t size, std::align_val_t align = std::align_val_t{0}) noexcept {
  count_new();
  if (size == 0) size = 1;
  const auto alignment = static_cast<std::size_t>(align);
  if (alignment <= __STDCPP_DEFAULT_NEW_ALIGNMENT__) return std::malloc(size);
  void* p = nullptr;
  return ::posix_memalign(&p, alignment, size) == 0 ? p : nullptr;
}

void* counted_new_or_throw(std::size_t size, std::align_val_t align = std::align_val_t{0}) {
  if (void* p = counted_new(size, align)) return p;
  throw std::bad_alloc{};
}

}  // namespace

// The global operator new and delete, every form: the memory is malloc's on
// both sides, which GCC cannot see.
#pragma GCC diagnostic ignored "-Wmismatched-new-delete"

void* operator new(std::size_t size) { return counted_new_or_throw(size); }
void* operator new[](std::size_t size) { return counted_new_or_throw(size); }
void* operator new(std::size_t size, const std::nothrow_t&) noexcept { return counted_new(size); }
void* operator new[](std::size_t size, const std::nothrow_t&) noexcept { return counted_new(size); }
void* operator new(std::size_t size, std::align_val_t align) { return counted_new_or_throw(size, align); }
void* operator new[](std::size_t size, std::align_val_t align) { return counted_new_or_throw(size, align); }
void* operator new(std::size_t size, std::align_val_t align, const std::nothrow_t&) noexcept {
  return counted_new(size, align);
}
void* operator new[](std::size_t size, std::align_val_t align, const std::nothrow_t&) noexcept {
  return counted_new(size, align);
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t, std::align_val_t) noexcept { std::free(p); }
void operator delete(void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete[](void* p, std::align_val_t, const std::nothrow_t&) noexcept { std::free(p); }

#if !PRIME_HOT_PATH_SANITIZED
// malloc and its kin, counted, then glibc's own. (Under a sanitizer its
// runtime interposes them: not here.)
extern "C" {
void* __libc_malloc(std::size_t size) noexcept;
void* __libc_calloc(std::size_t n, std::size_t size) noexcept;
void* __libc_realloc(void* p, std::size_t size) noexcept;
void __libc_free(void* p) noexcept;
void* __libc_memalign(std::size_t alignment, std::size_t size) noexcept;
}

namespace {
void count_malloc() noexcept {
  ++thread_mallocs;
  process_mallocs.fetch_add(1, std::memory_order_relaxed);
}
}  // namespace

extern "C" {
void* malloc(std::size_t size) noexcept {
  count_malloc();
  return __libc_malloc(size);
}
void* calloc(std::size_t n, std::size_t size) noexcept {
  count_malloc();
  return __libc_calloc(n, size);
}
void* realloc(void* p, std::size_t size) noexcept {
  count_malloc();
  return __libc_realloc(p, size);
}
void free(void* p) noexcept { __libc_free(p); }
void* aligned_alloc(std::size_t alignment, std::size_t size) noexcept {
  count_malloc();
  return __libc_memalign(alignment, size);
}
void* memalign(std::size_t alignment, std::size_t size) noexcept {
  count_malloc();
  return __libc_memalign(alignment, size);
}
int posix_memalign(void** out, std::size_t alignment, std::size_t size) noexcept {
  if (alignment % sizeof(void*) != 0 || !std::has_single_bit(alignment)) return EINVAL;
  count_malloc();
  void* p = __libc_memalign(alignment, size);
  if (p == nullptr) return ENOMEM;
  *out = p;
  return 0;
}
}
#endif

namespace prime::test {
namespace {

using namespace std::chrono_literals;

// Before any test runs, every page of code and static data the process has
// mapped is mapped in (read, and written back where it is private and
// writable: the libraries' data, .bss and lazily bound symbol tables), as
// mlockall(MCL_CURRENT) would without its privilege; and the binary is
// linked with -z now (tests/CMakeLists.txt). So is a process set up for
// real time (prime::lock_memory). A path a worker first takes late, inside
// a measured window (its first sleep after a slow turn on a loaded
// machine, say), then costs no fault for running code for the first time
// (a first call through a lazily bound symbol faulted so in a sync worker).
// What the windows count is what the paths themselves touch: the heap, the
// threads' stacks, the shared memory mapped since. Not under a sanitizer,
// whose shadow memory is huge and whose faults are not asserted.
bool page_in_code_and_static_data() {
  if (kSanitized) return false;
  std::ifstream maps{"/proc/self/maps"};
  const auto page = static_cast<std::uintptr_t>(::sysconf(_SC_PAGESIZE));
  std::uintptr_t previous_end = 0;
  bool previous_file = false;
  for (std::string line; std::getline(maps, line);) {
    std::istringstream fields{line};
    std::string range, perms, offset, device, inode, path;
    fields >> range >> perms >> offset >> device >> inode;
    std::getline(fields >> std::ws, path);
    const auto dash = range.find('-');
    std::uintptr_t begin = 0, end = 0;
    std::from_chars(range.data(), range.data() + dash, begin, 16);
    std::from_chars(range.data() + dash + 1, range.data() + range.size(), end, 16);
    const bool file = path.starts_with('/');
    const bool bss = path.empty() && previous_file && begin == previous_end;  // a library's, after its data
    if (perms.size() == 4 && perms[0] == 'r' && (file || bss)) {
      const bool write_back = perms[1] == 'w' && perms[3] == 'p';
      for (auto at = begin; at < end; at += page) {
        auto* byte = reinterpret_cast<volatile char*>(at);
        const char value = *byte;
        if (write_back) *byte = value;
      }
    }
    previous_end = end;
    previous_file = file;
  }
  return true;
}
[[maybe_unused]] const bool paged_in = page_in_code_and_static_data();

constexpr std::uint64_t kWarmUp = 2'000;
constexpr std::uint64_t kIterations = 100'000;

// What was counted up to now: allocations and minor page faults.
struct Counts {
  std::uint64_t news = 0;
  std::uint64_t mallocs = 0;
  std::uint64_t minor_faults = 0;

  Counts operator-(const Counts& before) const {
    return {news - before.news, mallocs - before.mallocs, minor_faults - before.minor_faults};
  }
};

std::uint64_t minor_faults(int who) {
  rusage usage{};
  ::getrusage(who, &usage);
  return static_cast<std::uint64_t>(usage.ru_minflt);
}
// The calling thread's.
Counts this_thread() { return {thread_news, thread_mallocs, minor_faults(RUSAGE_THREAD)}; }
// Every thread's.
Counts all_threads() {
  return {process_news.load(std::memory_order_relaxed), process_mallocs.load(std::memory_order_relaxed),
          minor_faults(RUSAGE_SELF)};
}

// Whether `path` made nothing over `iterations` on `where`: no operator new,
// and, without a sanitizer, no malloc and no minor fault.
::testing::AssertionResult made_nothing(const std::string& path, const char* where, const Counts& made,
                                        std::uint64_t iterations = kIterations) {
  const bool clean = made.news == 0 && (kSanitized || (made.mallocs == 0 && made.minor_faults == 0));
  auto result = clean ? ::testing::AssertionSuccess() : ::testing::AssertionFailure();
  result << path << ": " << iterations << " iterations after " << kWarmUp << " of warm-up made " << made.news
         << " operator new, ";
  if (kSanitized)
    return result << "malloc not counted, and " << made.minor_faults << " minor faults (not asserted) on " << where
                  << " (want no operator new: under a sanitizer that is all this test asserts)";
  return result << made.mallocs << " malloc and " << made.minor_faults << " minor faults on " << where
                << " (want 0 of each)";
}

// Runs `step(i)` kWarmUp times, then kIterations times measured; each step
// returns whether it saw what it should (checked after, not to allocate).
template <class Step>
void expect_steady(const std::string& path, Step step) {
  (void)this_thread();  // getrusage's code paged in before the window
  (void)all_threads();
  std::uint64_t wrong = 0;
  std::uint64_t i = 0;
  for (; i < kWarmUp; ++i) wrong += step(i) ? 0 : 1;
  const auto thread_before = this_thread();
  const auto all_before = all_threads();
  for (; i < kWarmUp + kIterations; ++i) wrong += step(i) ? 0 : 1;
  const auto all_after = all_threads();
  const auto thread_after = this_thread();
  EXPECT_EQ(wrong, 0u) << path << ": steps that did not see what they should";
  EXPECT_TRUE(made_nothing(path, "the calling thread", thread_after - thread_before));
  EXPECT_TRUE(made_nothing(path, "all threads", all_after - all_before));
}

// A message as a robot would send: trivially copyable, with its sequence.
struct Pose {
  std::uint64_t seq;
  double x, y, heading;
};
Pose pose(std::uint64_t seq) { return {seq, 0.5 * static_cast<double>(seq), 1.0, 0.25}; }
Pose integrate(const Pose& p) { return {p.seq + 1, p.x + 0.01, p.y, p.heading}; }
double distance(const Pose& p) { return p.x + p.y; }

struct Ask {
  std::uint64_t who;
  std::uint64_t n;
};
struct Answer {
  std::uint64_t who;
  std::uint64_t n;
};

// What a worker's thread made between the run of user code it does at
// iteration `first` and the one at `last` (a served block, a loop's chain).
// Written by the worker; read once the last run is known to be over. Its
// ending is rehearsed once in the warm-up, so that the real one, in the
// window of the thread that waits for it, runs no code for the first time
// (the first call of a lazily bound function takes a stack page more than
// the path).
struct WorkerWindow {
  std::atomic<std::uint64_t> rehearsal{~0ull};
  std::atomic<std::uint64_t> first{~0ull};
  std::atomic<std::uint64_t> last{~0ull};
  Counts thread_before{};
  Counts thread_after{};
  Counts all_before{};
  Counts all_after{};
  std::mutex mutex;
  std::condition_variable cv;
  bool rehearsed = false;
  bool done = false;

  // Runs `from` to `to` measured, after a warm-up of `from` runs.
  void aim(std::uint64_t from, std::uint64_t to) {
    rehearsal.store(from / 2);
    first.store(from);
    last.store(to);
  }
  // At run `n` of the worker's user code.
  void at(std::uint64_t n) {
    if (n == rehearsal.load(std::memory_order_relaxed)) {
      begin();
      end(rehearsed);
    } else if (n == first.load(std::memory_order_relaxed)) {
      begin();
    } else if (n == last.load(std::memory_order_relaxed)) {
      end(done);
    }
  }
  [[nodiscard]] bool wait() {
    std::unique_lock lock{mutex};
    return cv.wait_for(lock, 60s, [&] { return done; });
  }

 private:
  void begin() {
    (void)this_thread();  // getrusage's code paged in on this thread's path too
    thread_before = this_thread();
    all_before = all_threads();
  }
  void end(bool& flag) {
    all_after = all_threads();
    thread_after = this_thread();
    std::scoped_lock lock{mutex};  // notified under the lock: once the waiter sees the flag, this is done with it
    flag = true;
    cv.notify_all();
  }
};

// ---------------------------------------------------------------------------
// The counters themselves: they see what they count, so no test here passes
// for counting nothing.

int* volatile escaped_int = nullptr;   // so the allocations cannot be elided
void* volatile escaped_bytes = nullptr;

TEST(HotPathCounters, SeeOneOperatorNew) {
  const auto thread_before = this_thread();
  const auto all_before = all_threads();
  escaped_int = new int{7};
  const auto all_after = all_threads();
  const auto thread_after = this_thread();
  delete escaped_int;
  EXPECT_EQ((thread_after - thread_before).news, 1u);
  EXPECT_GE((all_after - all_before).news, 1u);
}

TEST(HotPathCounters, SeeOneMalloc) {
  if (kSanitized) GTEST_SKIP() << "under ASan/TSan malloc is the sanitizer runtime's: not interposed, not counted";
  const auto thread_before = this_thread();
  const auto all_before = all_threads();
  escaped_bytes = std::malloc(24);
  const auto all_after = all_threads();
  const auto thread_after = this_thread();
  std::free(escaped_bytes);
  EXPECT_EQ((thread_after - thread_before).mallocs, 1u);
  EXPECT_GE((all_after - all_before).mallocs, 1u);
}

// One page of fresh anonymous memory: its first touch is a minor fault.
class FreshPage {
 public:
  FreshPage() : size_{static_cast<std::size_t>(::sysconf(_SC_PAGESIZE))} {
    at_ = ::mmap(nullptr, size_, PROT_READ | PROT_WRITE, MAP_PRIVATE | MAP_ANONYMOUS, -1, 0);
  }
  FreshPage(const FreshPage&) = delete;
  FreshPage& operator=(const FreshPage&) = delete;
  ~FreshPage() {
    if (at_ != MAP_FAILED) ::munmap(at_, size_);
  }
  [[nodiscard]] bool mapped() const { return at_ != MAP_FAILED; }
  void touch() { *static_cast<volatile char*>(at_) = 1; }

 private:
  std::size_t size_;
  void* at_;
};

TEST(HotPathCounters, SeeOneFreshPageFault) {
  FreshPage page;
  ASSERT_TRUE(page.mapped());
  (void)this_thread();
  (void)all_threads();
  const auto thread_before = this_thread();
  const auto all_before = all_threads();
  page.touch();
  const auto all_after = all_threads();
  const auto thread_after = this_thread();
  if (kSanitized)
    GTEST_SKIP() << "under ASan/TSan minor faults are not asserted (the runtime maps shadow memory as memory is "
                    "touched); this touch counted "
                 << (thread_after - thread_before).minor_faults;
  EXPECT_EQ((thread_after - thread_before).minor_faults, 1u);
  EXPECT_GE((all_after - all_before).minor_faults, 1u);
}

// ---------------------------------------------------------------------------
// Shm topics: one process holds the publisher and the subscribers, and
// every step publishes and then reads, so each runs on this thread.

class ShmTopicHotPath : public ::testing::TestWithParam<Overflow> {
 protected:
  shm::Core core{unique_domain("hot")};
  // Each path has a topic of its own: a `block` publisher waits for every
  // subscriber of its topic, and only the path's own reads.
  std::string path(const std::string& what) const {
    return "shm " + what + (GetParam() == Overflow::block ? " (block)" : " (drop_oldest)");
  }
};

TEST_P(ShmTopicHotPath, LoanWritePublishTryReadRelease) {
  const auto qos = shm::TopicQos{.capacity = 64, .overflow = GetParam()};
  auto publisher = core.publisher<Pose>("hot/loan", qos);
  auto reader = core.subscribe<Pose>("hot/loan", {}, qos).subscribe();
  expect_steady(path("loan, write in place, publish, try_read, release the view"), [&](std::uint64_t i) {
    auto loan = publisher.loan();
    if (!loan) return false;
    **loan = pose(i);
    std::move(*loan).publish();
    auto got = reader.try_read();
    return got && got->value->seq == i;
  });
}

TEST_P(ShmTopicHotPath, PublishACopyReadUntilRelease) {
  const auto qos = shm::TopicQos{.capacity = 64, .overflow = GetParam()};
  auto publisher = core.publisher<Pose>("hot/copy", qos);
  auto reader = core.subscribe<Pose>("hot/copy", {}, qos).subscribe();
  const auto far = Clock::now() + 1h;
  expect_steady(path("publish(value), read_until, release the view"), [&](std::uint64_t i) {
    if (!publisher.publish(pose(i))) return false;
    auto got = reader.read_until(far);
    return got && got->value->seq == i;
  });
}

TEST_P(ShmTopicHotPath, LoanSomePublishBatchReadViewsRelease) {
  constexpr std::size_t kBatch = 8;
  const auto qos = shm::TopicQos{.capacity = 64, .overflow = GetParam()};
  auto publisher = core.publisher<Pose>("hot/batch", qos);
  auto batches = core.subscribe<Pose>("hot/batch", {}, qos).batches();
  const auto far = Clock::now() + 1h;
  expect_steady(path("loan_some(8), publish the batch, BatchReader read and try_read (Views), release"),
                [&](std::uint64_t i) {
                  auto batch = publisher.loan_some(kBatch);
                  if (!batch || batch->size() != kBatch) return false;
                  for (std::size_t k = 0; k < kBatch; ++k) (*batch)[k] = pose(i * kBatch + k);
                  std::move(*batch).publish();
                  // Half taken waiting (read), half as published now (try_read).
                  auto first = batches.read(kBatch / 2, far);
                  if (!first || first->size() != kBatch / 2 || (*first)[0].seq != i * kBatch) return false;
                  auto rest = batches.try_read(kBatch);
                  return rest.size() == kBatch / 2 && rest[kBatch / 2 - 1].seq == i * kBatch + kBatch - 1;
                });
}

TEST_P(ShmTopicHotPath, LoanSomePublishReadSomeRelease) {
  constexpr std::size_t kBatch = 8;
  const auto qos = shm::TopicQos{.capacity = 64, .overflow = GetParam()};
  auto publisher = core.publisher<Pose>("hot/some", qos);
  auto reader = core.subscribe<Pose>("hot/some", {}, qos).subscribe();
  std::vector<Sample<shm::View<Pose>>> got;
  got.reserve(kBatch);  // a worker's batch keeps its room (spawn_reader reserves it once)
  const auto far = Clock::now() + 1h;
  expect_steady(path("loan_some(8), publish the batch, read_some into a kept vector, release the views"),
                [&](std::uint64_t i) {
                  auto batch = publisher.loan_some(kBatch);
                  if (!batch || batch->size() != kBatch) return false;
                  for (std::size_t k = 0; k < kBatch; ++k) (*batch)[k] = pose(i * kBatch + k);
                  std::move(*batch).publish();
                  got.clear();
                  auto n = reader.read_some(got, kBatch, far);
                  const bool ok = n && *n == kBatch && got.back().value->seq == i * kBatch + kBatch - 1;
                  got.clear();
                  return ok;
                });
}

TEST_P(ShmTopicHotPath, CollectorOfATopic) {
  const auto qos = shm::TopicQos{.capacity = 64, .overflow = GetParam()};
  auto publisher = core.publisher<Pose>("hot/collected", qos);
  auto newest = collector(core, core.subscribe<Pose>("hot/collected", {}, qos));
  expect_steady(path("publish, collector call (the newest view), release"), [&](std::uint64_t i) {
    if (!publisher.publish(pose(i))) return false;
    return newest(Token{})->seq == i;
  });
}

INSTANTIATE_TEST_SUITE_P(Overflow, ShmTopicHotPath, ::testing::Values(Overflow::drop_oldest, Overflow::block),
                         [](const auto& info) { return info.param == Overflow::block ? "block" : "drop_oldest"; });

// ---------------------------------------------------------------------------
// Shm services: this thread calls, the core's worker serves; the served
// block counts its own thread's share.

class ShmServiceHotPath : public ::testing::Test {
 protected:
  // Before the core: its workers, which write into them, stop first.
  WorkerWindow worker;
  WorkerWindow second_worker;
  shm::Core core{unique_domain("hot")};
};

TEST_F(ShmServiceHotPath, CallAndServe) {
  core.serve("hot/echo", [this](const Ask& ask) {
    worker.at(ask.n);
    return Answer{ask.who, ask.n + 1};
  });
  auto echo = core.chain<Ask, Answer>("hot/echo", {.timeout = 10s});
  worker.aim(kWarmUp, kWarmUp + kIterations - 1);
  expect_steady("shm service call (call(x)) and serve", [&](std::uint64_t i) {
    auto answer = echo.call(Ask{7, i});
    return answer && answer->n == i + 1;
  });
  ASSERT_TRUE(worker.wait());
  EXPECT_TRUE(made_nothing("shm service serve", "the serving worker's thread", worker.thread_after - worker.thread_before,
                           kIterations - 1));
}

TEST_F(ShmServiceHotPath, CallInPlaceAndServe) {
  // No spin on either side: the worker and the caller sleep on their futex
  // each call (CallAndServe spins first, as by default).
  core.serve("hot/in_place", [this](const Ask& ask) {
    worker.at(ask.n);
    return Answer{ask.who, ask.n + 1};
  }, {.spin = 0us});
  auto echo = core.chain<Ask, Answer>("hot/in_place", {.timeout = 10s, .spin = 0us});
  worker.aim(kWarmUp, kWarmUp + kIterations - 1);
  expect_steady("shm service call_in_place and serve", [&](std::uint64_t i) {
    bool right = false;
    auto done = echo.call_in_place([&](Ask& ask) { ask = {7, i}; }, [&](const Answer& a) { right = a.n == i + 1; });
    return done && right;
  });
  ASSERT_TRUE(worker.wait());
  EXPECT_TRUE(made_nothing("shm service serve (in place)", "the serving worker's thread",
                           worker.thread_after - worker.thread_before, kIterations - 1));
}

// Three threads take part (the caller and two workers): on two CPUs, none
// spins, or they would take turns at the scheduler's pace.
TEST_F(ShmServiceHotPath, LinkedCallThroughTwoServices) {
  core.serve("hot/first", [this](const Ask& ask) {
    worker.at(ask.n);
    return Ask{ask.who, ask.n + 1};
  }, {.spin = 0us});
  core.serve("hot/second", [this](const Ask& ask) {
    second_worker.at(ask.n);
    return Answer{ask.who, ask.n + 1};
  }, {.spin = 0us});
  auto both = core.chain<Ask, Ask>("hot/first", {.timeout = 10s}) | core.chain<Ask, Answer>("hot/second", {.spin = 0us});
  worker.aim(kWarmUp, kWarmUp + kIterations - 1);
  second_worker.aim(kWarmUp + 1, kWarmUp + kIterations);
  expect_steady("shm linked service call (a | b), forwarded worker to worker", [&](std::uint64_t i) {
    auto answer = both.call(Ask{7, i});
    return answer && answer->n == i + 2;
  });
  ASSERT_TRUE(worker.wait());
  ASSERT_TRUE(second_worker.wait());
  EXPECT_TRUE(made_nothing("shm linked call, first service", "its worker's thread",
                           worker.thread_after - worker.thread_before, kIterations - 1));
  EXPECT_TRUE(made_nothing("shm linked call, second service", "its worker's thread",
                           second_worker.thread_after - second_worker.thread_before, kIterations - 1));
}

// ---------------------------------------------------------------------------
// sync: the matcher on this thread, values offered in a fixed order; and
// prime::sync over two Shm topics, its input workers matching while this
// thread publishes and reads the sets.

TEST(SyncHotPath, ApproximateTimeMatcherInSteadyState) {
  LocalSource<Synced<Pose, Pose>> out{"sets", {}, {}, Graph{}};
  auto sets = out.subscribe();
  const auto policy = approximate_time({.min_interval = {10ms, 10ms}});
  prime::detail::Synchronizer<Pose, Pose> matcher{policy, {policy.depth, policy.depth}, out};
  const auto t0 = Clock::now();
  expect_steady("sync matching (approximate_time), offered on this thread", [&](std::uint64_t i) {
    const auto stamp = t0 + 10ms * static_cast<Clock::rep>(i);
    matcher.offer<0>({pose(i), stamp}, {});
    matcher.offer<1>({pose(i), stamp}, {});
    auto set = sets.try_read();
    return set && std::get<0>(set->value).seq == i && std::get<1>(set->value).seq == i;
  });
}

TEST(SyncHotPath, WithinToleranceMatcherInSteadyState) {
  LocalSource<Synced<Pose, Pose>> out{"sets", {}, {}, Graph{}};
  auto sets = out.subscribe();
  prime::detail::Synchronizer<Pose, Pose> matcher{within_tolerance(1ms), {32, 32}, out};
  const auto t0 = Clock::now();
  expect_steady("sync matching (within_tolerance), offered on this thread", [&](std::uint64_t i) {
    const auto stamp = t0 + 10ms * static_cast<Clock::rep>(i);
    matcher.offer<0>({pose(i), stamp}, {});
    matcher.offer<1>({pose(i), stamp}, {});
    auto set = sets.try_read();
    return set && std::get<0>(set->value).seq == i && std::get<1>(set->value).seq == i;
  });
}

// Three threads take part (this one and the sync's two input workers): on
// two CPUs, the inputs' readers sleep at once rather than spin.
TEST(SyncHotPath, ApproximateTimeOverShmTopics) {
  shm::Core core{unique_domain("hot")};
  auto lidar = core.publisher<Pose>("hot/lidar");
  auto odom = core.publisher<Pose>("hot/odom");
  auto sets = sync(approximate_time({.min_interval = {10ms, 10ms}}), core.subscribe<Pose>("hot/lidar", {.spin = 0us}),
                   core.subscribe<Pose>("hot/odom", {.spin = 0us}));
  auto reader = sets.subscribe();
  const auto t0 = Clock::now();
  const auto far = Clock::now() + 1h;
  expect_steady("prime::sync(approximate_time) of two shm topics: publish both, read the set, release",
                [&](std::uint64_t i) {
                  const auto stamp = t0 + 10ms * static_cast<Clock::rep>(i);
                  if (!lidar.publish(pose(i), stamp) || !odom.publish(pose(i), stamp)) return false;
                  auto set = reader.read_until(far);
                  return set && std::get<0>(set->value)->seq == i && std::get<1>(set->value)->seq == i;
                });
}

// ---------------------------------------------------------------------------
// The collector of an in-process source (Liberty).

TEST(CollectorHotPath, CollectorOfALibertySource) {
  liberty::Core core;
  Event<Pose> poses;
  auto newest = collector(core, core.source(poses, "poses"));
  expect_steady("liberty event emit, collector call", [&](std::uint64_t i) {
    poses.emit(pose(i));
    return newest(Token{}).seq == i;
  });
}

TEST(CollectorHotPath, CollectorOrNothingOfALibertySource) {
  liberty::Core core;
  Event<Pose> poses;
  auto newest = collector(core, core.source(poses, "poses"), or_nothing);
  expect_steady("liberty event emit, collector(or_nothing) call", [&](std::uint64_t i) {
    poses.emit(pose(i));
    const auto got = newest(Token{});
    return got && got->seq == i;
  });
}

// ---------------------------------------------------------------------------
// Chain steps over trivially copyable values.

TEST(ChainHotPath, RadiantChainStep) {
  radiant::Core core;
  auto step = core.chain(integrate) | core.chain(integrate) | core.chain(distance);
  double total = 0;
  expect_steady("radiant chain step (Pose -> Pose -> double)", [&](std::uint64_t i) {
    total += step(pose(i));
    return total > 0;
  });
}

TEST(ChainHotPath, LibertyChainStep) {
  liberty::Core core;
  auto same = core.chain(integrate) | core.chain(integrate);  // one type throughout: a sequence of steps
  auto step = same | core.chain(distance);                     // then another type: a linked step
  double total = 0;
  expect_steady("liberty chain step (Pose -> Pose -> Pose -> double)", [&](std::uint64_t i) {
    total += step(pose(i));
    return total > 0;
  });
}

// ---------------------------------------------------------------------------
// The periodic tick: the loop's chain counts its own thread between two of
// its runs (and every thread of the process, this one asleep meanwhile).

// Timer slack of 1 ns for the threads made while it lives (a thread
// inherits its maker's): a short period is then kept, not stretched to the
// default 50 us, and 100,000 ticks take about a second.
class TightTimerSlack {
 public:
  TightTimerSlack() : before_{::prctl(PR_GET_TIMERSLACK, 0, 0, 0, 0)} { ::prctl(PR_SET_TIMERSLACK, 1, 0, 0, 0); }
  TightTimerSlack(const TightTimerSlack&) = delete;
  TightTimerSlack& operator=(const TightTimerSlack&) = delete;
  ~TightTimerSlack() {
    if (before_ > 0) ::prctl(PR_SET_TIMERSLACK, before_, 0, 0, 0);
  }

 private:
  int before_;
};

template <class Core, class Step>
void expect_ticks_steady(const std::string& path, Core& core, Step step) {
  WorkerWindow worker;
  worker.aim(kWarmUp, kWarmUp + kIterations);
  std::optional<Loop> loop;
  {
    TightTimerSlack slack;
    loop.emplace(every(
        core, 5us,
        [&worker, step, runs = std::uint64_t{0}, p = pose(0), total = 0.0](Token) mutable {
          p.seq = runs;
          total += step(p);
          worker.at(runs++);
        },
        {.name = "hot", .deadline = 10s}));
  }
  ASSERT_TRUE(worker.wait()) << path << ": the loop did not tick " << kWarmUp + kIterations << " times in 60 s";
  loop->stop();
  EXPECT_TRUE(made_nothing(path, "the loop's thread", worker.thread_after - worker.thread_before));
  EXPECT_TRUE(made_nothing(path, "all threads", worker.all_after - worker.all_before));
  EXPECT_EQ(loop->stats().overruns, 0u);
}

TEST(LoopHotPath, PeriodicTickOfALibertyCoreRunningALibertyChain) {
  liberty::Core core;
  auto step = core.chain(integrate) | core.chain(distance);
  expect_ticks_steady("periodic tick (every) of a liberty core, running a liberty chain", core, step);
}

TEST(LoopHotPath, PeriodicTickOfAnShmCoreRecordingInItsRegistry) {
  shm::Core core{unique_domain("hot")};
  auto step = core.chain(integrate) | core.chain(distance);
  expect_ticks_steady("periodic tick (every) of an shm core (statistics in the domain's registry), running a chain",
                      core, step);
}

}  // namespace
}  // namespace prime::test
