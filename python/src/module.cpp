// prime._prime: the Shm medium for Python, over its run-time-typed handles
// (Core::raw_subscription, raw_publisher, raw_chain, raw_serve). A sample is handed to
// Python as an object that holds its View and exports its bytes, read-only,
// in place in shared memory; numpy wraps them with no copy (prime/shm.py),
// and the sample stays held while any array made from it lives.
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <Python.h>
#include <pthread.h>

#include <algorithm>
#include <chrono>
#include <functional>
#include <cstring>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <unordered_set>
#include <utility>
#include <vector>

#include "prime/shm.hpp"

namespace py = pybind11;
namespace shm = prime::shm;
using prime::Clock;
using namespace std::chrono_literals;

namespace {

// A blocking wait gives up the GIL and looks for signals (Ctrl-C) this often.
constexpr auto kSignalCheck = 100ms;

// Seconds from Python as a duration: NaN and negative refused, anything
// beyond a century taken as forever (Clock::duration::max()).
Clock::duration duration_of(double seconds, const char* what) {
  if (!(seconds >= 0)) throw prime::Failure{{prime::Errc::invalid_argument, std::string{what} + " must be 0 or more seconds"}};
  if (seconds > 3.2e9) return Clock::duration::max();
  return std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>{seconds});
}

Clock::time_point deadline_after(std::optional<double> timeout) {
  if (!timeout) return Clock::time_point::max();
  const auto wait = duration_of(*timeout, "a timeout");
  const auto now = Clock::now();
  return wait >= Clock::time_point::max() - now ? Clock::time_point::max() : now + wait;
}

// A service call's timeout: whole milliseconds, rounded up (0 would mean the
// service's own); none: the service's own.
std::chrono::milliseconds call_timeout(std::optional<double> timeout) {
  if (!timeout) return std::chrono::milliseconds{0};
  const auto wait = duration_of(*timeout, "a timeout");
  if (wait == Clock::duration::max()) return std::chrono::hours{24 * 365 * 100};  // a century: no deadline to overflow
  return std::max(std::chrono::milliseconds{1}, std::chrono::ceil<std::chrono::milliseconds>(wait));
}

// A stamp from Python (seconds of the steady clock), or now.
Clock::time_point stamp_of(std::optional<double> seconds) {
  return seconds ? Clock::time_point{duration_of(*seconds, "a stamp")} : Clock::now();
}

double seconds_of(Clock::time_point t) { return std::chrono::duration<double>{t.time_since_epoch()}.count(); }

// Runs `f` without the GIL and returns what it returns. The GIL is taken
// back by a plain call, not by a destructor (py::gil_scoped_release's): at
// the interpreter's exit that call ends a daemon thread still in here by
// unwinding it (pthread_exit), which through a destructor, noexcept, would
// be std::terminate instead.
template <class F>
auto without_gil(F&& f) {
  PyThreadState* state = PyEval_SaveThread();
  std::optional<decltype(f())> result;
  try {
    result.emplace(f());
  } catch (...) {
    PyEval_RestoreThread(state);
    throw;
  }
  PyEval_RestoreThread(state);  // outside the try: the unwind it may start is not caught
  return std::move(*result);
}

// Handles made before a fork() are the parent's. The child inherits copies
// of them, whose use would act on the parent's subscriber slots, loans and
// lease, and whose destruction would free those (or take the parent out of
// the domain). So in the child they refuse use, and when Python lets them
// go they are left as they are: their memory is all the child loses. Every
// handle is made, used and let go with the GIL held, which the thread that
// forks holds too, so these sets need no lock.
std::unordered_set<const void*>& live_handles() {
  static std::unordered_set<const void*> handles;
  return handles;
}
std::unordered_set<const void*>& inherited_handles() {
  static std::unordered_set<const void*> handles;
  return handles;
}
// Python's main thread, the one its signal handlers (Ctrl-C) run on: in a
// child of fork(), the thread that forked, as Python makes it.
unsigned long main_thread = 0;

void on_fork_in_child() {
  inherited_handles().merge(live_handles());
  live_handles().clear();
  main_thread = PyThread_get_thread_ident();
}

// Throws unless `handle` was made by this process.
void check_own(const void* handle) {
  if (inherited_handles().contains(handle))
    throw prime::Failure{{prime::Errc::invalid_argument,
                          "this handle was made before the process forked: it is its parent's (make a new "
                          "prime.shm.Domain in the child)"}};
}

// A handle's deleter: a handle the parent made is left alone.
template <class T>
struct ParentsOnly {
  void operator()(T* handle) const {
    if (inherited_handles().contains(handle)) return;
    live_handles().erase(handle);
    delete handle;
  }
};
// A core is stopped without the GIL: its services' workers may be waiting
// for it to finish a call, and each lets its Python function go with it.
// One let go from inside its own service's function (which could not wait
// for itself) is left running.
template <>
struct ParentsOnly<shm::Core> {
  void operator()(shm::Core* core) const;
};
template <class T>
using Handle = std::unique_ptr<T, ParentsOnly<T>>;

template <class T, class... A>
Handle<T> make_handle(A&&... args) {
  Handle<T> handle{new T(std::forward<A>(args)...)};
  live_handles().insert(handle.get());
  return handle;
}
template <class T>
std::shared_ptr<T> share_handle(T&& value) {
  std::shared_ptr<T> handle{new T(std::move(value)), ParentsOnly<T>{}};
  live_handles().insert(handle.get());
  return handle;
}

// A sample taken from a topic: its bytes stay held in the ring (counted in
// the subscriber's max_held) until this object is gone.
struct Held {
  prime::Sample<shm::View<shm::Bytes>> sample;
};

// Waits for `read(deadline)` (a std::expected) without the GIL, in slices
// that look for signals (Ctrl-C) between them, up to `timeout` (None:
// forever); returns its value or throws its error. A slice's end is not the
// caller's: nothing yet, or no room to hold another sample yet (one held
// elsewhere may be released meanwhile).
template <class F>
auto wait_for(F&& read, std::optional<double> timeout) {
  const auto deadline = deadline_after(timeout);
  while (true) {
    auto got = without_gil([&] { return std::optional{read(std::min(deadline, Clock::now() + kSignalCheck))}; });
    if (*got) return std::move(**got);
    const auto code = (*got).error().code;
    if ((code != prime::Errc::timeout && code != prime::Errc::held_limit) || Clock::now() >= deadline)
      throw prime::Failure{(*got).error()};
    if (PyErr_CheckSignals() != 0) throw py::error_already_set();
  }
}

// One subscriber of a topic: its source, and its reader (until it is given
// to a sync, which reads the source with readers of its own). Reads are
// serialised (a Reader is read by one thread at a time).
struct Subscriber {
  shm::Subscription<shm::Bytes> source;
  std::optional<prime::Reader<shm::View<shm::Bytes>>> reader;
  std::mutex mutex;

  explicit Subscriber(shm::Subscription<shm::Bytes> s) : source{std::move(s)}, reader{source.subscribe()} {}

  prime::Reader<shm::View<shm::Bytes>>& own() {
    check_own(this);
    if (!reader)
      throw prime::Failure{{prime::Errc::invalid_argument, "the subscriber of '" + source.name() + "' was given to a sync"}};
    return *reader;
  }

  std::shared_ptr<Held> read(std::optional<double> timeout) {
    auto sample = wait_for(
        [&](Clock::time_point until) {
          std::scoped_lock lock{mutex};
          return own().read_until(until);
        },
        timeout);
    return share_handle(Held{std::move(sample)});
  }

  // Up to `max` samples taken at once (what is there once one is, and at
  // most what the topic's max_held leaves), waiting up to `timeout` for the
  // first as read() does.
  std::vector<std::shared_ptr<Held>> read_batch(std::size_t max, std::optional<double> timeout) {
    if (max == 0) throw prime::Failure{{prime::Errc::invalid_argument, "a batch holds at least one sample"}};
    std::vector<prime::Sample<shm::View<shm::Bytes>>> taken;
    wait_for(
        [&](Clock::time_point until) {
          std::scoped_lock lock{mutex};
          return own().read_some(taken, max, until);
        },
        timeout);
    std::vector<std::shared_ptr<Held>> out;
    out.reserve(taken.size());
    for (auto& sample : taken) out.push_back(share_handle(Held{std::move(sample)}));
    return out;
  }

  std::optional<std::shared_ptr<Held>> try_read() {
    auto got = without_gil([&] {
      std::scoped_lock lock{mutex};
      return own().try_read();
    });
    if (!got) return std::nullopt;
    return share_handle(Held{std::move(*got)});
  }

  // Given to a sync, which reads its source: its own reader (and slot) let go.
  void give() {
    without_gil([&] {
      std::scoped_lock lock{mutex};
      reader.reset();
      return true;
    });
  }
};

// A sync of 2 to prime::kMaxSyncInputs subscribers' sources, as C++'s
// prime::sync makes it (its workers in the core's runtime): a reader of its
// sets, each the samples of one set in the order of the sources.
class SyncReader {
 public:
  using Set = std::vector<prime::Sample<shm::View<shm::Bytes>>>;

  // C++'s sync of each number of inputs it takes is compiled in; the one
  // of sources.size() starts.
  SyncReader(const prime::SyncPolicy& policy, std::vector<shm::Subscription<shm::Bytes>> sources) {
    const bool started = [&]<std::size_t... Extra>(std::index_sequence<Extra...>) {
      return ((sources.size() == Extra + 2 && (start(policy, sources, std::make_index_sequence<Extra + 2>{}), true)) ||
              ...);
    }(std::make_index_sequence<prime::kMaxSyncInputs - 1>{});
    if (!started)  // checked before the subscribers are given
      throw prime::Failure{{prime::Errc::invalid_argument, "a sync of " + std::to_string(sources.size()) + " inputs"}};
  }

  std::vector<std::shared_ptr<Held>> read(std::optional<double> timeout) {
    check_own(this);
    auto set = wait_for(
        [&](Clock::time_point until) {
          std::scoped_lock lock{mutex_};
          return read_(until);
        },
        timeout);
    std::vector<std::shared_ptr<Held>> out;
    for (auto& sample : set) out.push_back(share_handle(Held{std::move(sample)}));
    return out;
  }

 private:
  template <std::size_t... I>
  void start(const prime::SyncPolicy& policy, const std::vector<shm::Subscription<shm::Bytes>>& s, std::index_sequence<I...>) {
    auto synced = prime::sync(policy, s[I]...);
    auto reader = std::make_shared<decltype(synced.subscribe())>(synced.subscribe());
    read_ = [synced, reader](Clock::time_point until) -> std::expected<Set, prime::Error> {
      auto got = reader->read_until(until);
      if (!got) return std::unexpected(std::move(got.error()));
      auto& parts = got->value;
      Set set;
      (set.push_back({std::move(std::get<I>(parts)), parts.stamps[I]}), ...);
      return set;
    };
  }

  std::function<std::expected<Set, prime::Error>(Clock::time_point)> read_;
  std::mutex mutex_;
};

prime::SyncPolicy policy_of(const std::string& kind, double tolerance, std::size_t depth, std::optional<double> max_span,
                            const std::vector<double>& min_interval, double age_penalty, int trigger) {
  auto seconds = [](double s, const char* what) { return duration_of(s, what); };
  prime::SyncPolicy p{prime::SyncPolicy::Kind::latest_of_each};
  if (kind == "exact_time") {
    p = prime::exact_time;
  } else if (kind == "within_tolerance") {
    p = prime::within_tolerance(seconds(tolerance, "a tolerance"));
  } else if (kind == "approximate_time") {
    p.kind = prime::SyncPolicy::Kind::approximate_time;
    if (max_span) p.max_span = seconds(*max_span, "a max_span");
    if (min_interval.size() > prime::kMaxSyncInputs)
      throw prime::Failure{{prime::Errc::invalid_argument, "min_interval names more inputs than a sync takes"}};
    for (std::size_t i = 0; i < min_interval.size(); ++i) p.min_interval[i] = seconds(min_interval[i], "a min_interval");
    if (!(age_penalty >= 0)) throw prime::Failure{{prime::Errc::invalid_argument, "age_penalty must be 0 or more"}};
    p.age_penalty = age_penalty;
  } else if (kind == "latest_of_each") {
    p = prime::latest_of_each_on(trigger);
  } else {
    throw prime::Failure{{prime::Errc::invalid_argument, "no sync policy '" + kind + "'"}};
  }
  p.depth = depth;
  return p;
}

// A publisher and its lock: one thread at a time loans and publishes. A
// `block` topic's publish or loan holds the lock while it waits for room,
// up to block_timeout, without the GIL.
class Publisher {
 public:
  explicit Publisher(shm::Publisher<shm::Bytes> p) : publisher_{std::move(p)} {}

  // Runs `f(publisher)` without the GIL, with the lock; loans dropped
  // meanwhile go back to the ring before the lock does.
  template <class F>
  auto use(F&& f) {
    return without_gil([&] {
      std::scoped_lock lock{mutex_};
      hand_back_dropped();
      auto result = f(publisher_);
      hand_back_dropped();
      return result;
    });
  }

  void publish(const py::buffer& data, std::optional<double> stamp) {
    check_own(this);
    const auto info = data.request();
    if (!PyBuffer_IsContiguous(info.view(), 'C'))
      throw prime::Failure{{prime::Errc::invalid_argument, "a message must be one contiguous block of bytes"}};
    const auto when = stamp_of(stamp);
    const std::span bytes{static_cast<const std::byte*>(info.ptr), static_cast<std::size_t>(info.size * info.itemsize)};
    const auto sent = use([&](auto& publisher) { return publisher.publish(bytes, when); });
    if (!sent) throw prime::Failure{sent.error()};
  }

  // A loan Python let go of unpublished, with the GIL held. It must not
  // wait for the lock: a `block` publish on another thread may hold it for
  // up to block_timeout, and every Python thread would wait with this one.
  // It goes back now if the lock is free, else when its holder lets go of
  // it (or, if that holder has just looked, at the next use or the end).
  void drop(shm::Loan<shm::Bytes> loan) {
    {
      std::scoped_lock lock{dropped_mutex_};
      dropped_.push_back(std::move(loan));
    }
    if (std::unique_lock lock{mutex_, std::try_to_lock}; lock) hand_back_dropped();
  }

 private:
  void hand_back_dropped() {  // with mutex_ held
    std::vector<shm::Loan<shm::Bytes>> loans;
    std::scoped_lock lock{dropped_mutex_};
    loans.swap(dropped_);
  }  // `loans` ends after the lock: each hands its chunk back

  shm::Publisher<shm::Bytes> publisher_;
  std::mutex mutex_;
  std::mutex dropped_mutex_;  // held only to move loans in or out, never while waiting
  std::vector<shm::Loan<shm::Bytes>> dropped_;  // ends before publisher_: handed back first
};

// A message loaned in the topic's ring, written in place through its
// exported (writable) bytes, then published. prime/shm.py publishes only
// once no export of the bytes is left; a loan not published goes back to
// the ring when this object goes, which no export outlives (each holds it).
struct LoanedMessage {
  Publisher* publisher;  // kept alive by this object (keep_alive)
  std::optional<shm::Loan<shm::Bytes>> loan;

  LoanedMessage(Publisher* p, shm::Loan<shm::Bytes> l) : publisher{p}, loan{std::move(l)} {}
  LoanedMessage(const LoanedMessage&) = delete;
  LoanedMessage& operator=(const LoanedMessage&) = delete;
  ~LoanedMessage() {
    if (loan) publisher->drop(std::move(*loan));
  }

  void publish(std::optional<double> stamp) {
    check_own(this);
    if (!loan) throw prime::Failure{{prime::Errc::invalid_argument, "this loan was published already"}};
    const auto when = stamp_of(stamp);
    publisher->use([&](auto&) {
      std::move(*loan).publish(when);
      loan.reset();
      return true;
    });
  }
};

// Asked by a call on the main thread each time it has waited a slice with
// no answer: whether a signal's handler raised (KeyboardInterrupt), whose
// exception is then this thread's to throw once it has the GIL back.
bool signal_raised() {
  const auto gil = PyGILState_Ensure();
  const bool raised = PyErr_CheckSignals() != 0;
  PyGILState_Release(gil);
  return raised;
}

struct Client {
  shm::ServiceChain<shm::Bytes, shm::Bytes> chain;

  // On the main thread the call gives up at a signal's exception (Ctrl-C),
  // as a read does; elsewhere it waits out its timeout (Python runs signal
  // handlers only on the main thread).
  py::bytes call(const py::buffer& request) const {
    check_own(this);
    const std::function<bool()> give_up = PyThread_get_thread_ident() == main_thread ? signal_raised : nullptr;
    const auto info = request.request();
    if (!PyBuffer_IsContiguous(info.view(), 'C'))
      throw prime::Failure{{prime::Errc::invalid_argument, "a request must be one contiguous block of bytes"}};
    const auto size = static_cast<std::size_t>(info.size * info.itemsize);
    std::string reply;
    const auto done = without_gil([&] {
      return chain.call_in_place(
          [&](std::span<std::byte> to) {
            std::memcpy(to.data(), info.ptr, std::min(size, to.size()));
            return size;  // over the room: the call fails with too_large
          },
          [&](std::span<const std::byte> from) {
            reply.assign(reinterpret_cast<const char*>(from.data()), from.size());
          },
          give_up);
    });
    if (PyErr_Occurred() != nullptr) throw py::error_already_set();  // given up (or answered just after)
    if (!done) throw prime::Failure{done.error()};
    return py::bytes{reply};
  }
};

// A message type from Python: checked as a C++ compiler would have made it.
shm::Core::RawType type_of(const std::string& name, std::size_t size, std::size_t alignment, std::uint32_t layout,
                           std::string schema) {
  auto refuse = [&](const std::string& why) {
    throw prime::Failure{{prime::Errc::invalid_argument, "type '" + name + "': " + why}};
  };
  if (name.empty()) refuse("a type needs its C++ name");
  if (size == 0) refuse("a message has at least one byte");
  if (alignment == 0 || (alignment & (alignment - 1)) != 0 || alignment > 4096)
    refuse("alignment " + std::to_string(alignment) + " is not a power of two up to 4096");
  if (size % alignment != 0)
    refuse("its size, " + std::to_string(size) + ", is not a multiple of its alignment, " + std::to_string(alignment));
  return {prime::Fingerprint::named(name, size, alignment, layout), std::move(schema)};
}

// What a Python exception raised in a service's function says to its
// caller: a prime.Error keeps its code; anything else is block_failed,
// named by its type. Called with the GIL held.
prime::Failure failure_of(py::error_already_set& e) {
  const std::string text = py::str(e.value());
  if (e.matches(py::module_::import("prime").attr("Error"))) {
    const std::string code = py::str(e.value().attr("code"));
    for (int value = 0; value < 64; ++value)
      if (const auto errc = prime::errc_from(value); errc && prime::to_string(*errc) == code)
        return prime::Failure{{*errc, py::str(e.value().attr("message"))}};
  }
  return prime::Failure{{prime::Errc::block_failed, std::string{py::str(e.type().attr("__name__"))} + ": " + text}};
}

// The core whose service's Python function this thread is running, if
// any: stopping that core from here would wait for this very thread.
thread_local const shm::Core* serving_core = nullptr;

// A Python function a service's workers call: `fn(bytes) -> bytes-like`.
// Its reference is let go with the GIL, wherever the last worker ends
// (never after the interpreter is gone: prime.shm stops serving at exit).
class ServiceFunction {
 public:
  ServiceFunction(const shm::Core& core, py::function fn) : core_{&core}, fn_{new py::function{std::move(fn)}} {}
  ServiceFunction(const ServiceFunction&) = delete;
  ServiceFunction& operator=(const ServiceFunction&) = delete;
  ~ServiceFunction() {
    if (!Py_IsInitialized()) return;  // the interpreter is gone: the reference with it
    py::gil_scoped_acquire gil;
    delete fn_;
  }

  // One request's reply, written into `out`; the request is copied into a
  // bytes object (it is valid only during the call; a Python function may
  // keep what it is given).
  std::size_t operator()(const std::byte* request, std::size_t size, std::byte* out, std::size_t capacity) const {
    py::gil_scoped_acquire gil;
    serving_core = core_;
    struct Done {
      ~Done() { serving_core = nullptr; }
    } done;
    try {
      py::object reply = (*fn_)(py::bytes(reinterpret_cast<const char*>(request), size));
      const py::buffer buffer = reply;
      const auto info = buffer.request();
      if (!PyBuffer_IsContiguous(info.view(), 'C'))
        throw prime::Failure{{prime::Errc::invalid_argument, "a reply must be one contiguous block of bytes"}};
      const auto n = static_cast<std::size_t>(info.size * info.itemsize);
      if (n > capacity)
        throw prime::Failure{{prime::Errc::too_large, "a reply of " + std::to_string(n) + " bytes exceeds the " +
                                                          std::to_string(capacity) + " bytes it may take"}};
      if (n > 0) std::memcpy(out, info.ptr, n);
      return n;
    } catch (py::error_already_set& e) {
      throw failure_of(e);
    }
  }

 private:
  const shm::Core* core_;  // which runs it
  py::function* fn_;       // deleted with the GIL held
};

void ParentsOnly<shm::Core>::operator()(shm::Core* core) const {
  if (inherited_handles().contains(core) || serving_core == core) return;
  live_handles().erase(core);
  without_gil([&] {
    core->stop();
    delete core;
    return true;
  });
}

// Stops `core`'s services and syncs, waiting for a call in progress:
// without the GIL, which that call may need.
void stop(shm::Core& core) {
  check_own(&core);
  if (serving_core == &core)
    throw prime::Failure{{prime::Errc::invalid_argument,
                          "a domain cannot be closed from inside one of its services' functions: closing waits for "
                          "every call in progress, this one too"}};
  without_gil([&] { return (core.stop(), true); });
}

py::dict topic_info(const shm::RegistrySnapshot::Topic& t) {
  py::dict d;
  d["name"] = t.name;
  d["type"] = t.type;
  d["schema"] = t.schema;
  d["size"] = t.fingerprint.size;
  d["raw"] = t.fingerprint == prime::Fingerprint::of<shm::Bytes>();
  d["max_message_size"] = t.qos.max_message_size;
  return d;
}

}  // namespace

PYBIND11_MODULE(_prime, m) {
  m.doc() = "Prime's Shm medium (see the prime package)";
  pthread_atfork(nullptr, nullptr, on_fork_in_child);
  main_thread = py::module_::import("threading").attr("main_thread")().attr("ident").cast<unsigned long>();

  // A prime::Failure becomes the prime package's exception for its code.
  py::register_exception_translator([](std::exception_ptr p) {
    try {
      if (p) std::rethrow_exception(p);
    } catch (const prime::Failure& failure) {
      const auto& e = failure.error();
      const std::string code{prime::to_string(e.code)};
      auto type = py::module_::import("prime").attr("_error_class")(code);
      // A message may carry another process's bytes (a block's exception text).
      auto message = py::reinterpret_steal<py::object>(
          PyUnicode_DecodeUTF8(e.message.data(), static_cast<py::ssize_t>(e.message.size()), "replace"));
      PyErr_SetObject(type.ptr(), py::make_tuple(code, message).ptr());
    }
  });

  py::list codes;  // every prime::Errc, as C++ names it
  for (int value = 0; value < 64; ++value)
    if (const auto code = prime::errc_from(value)) codes.append(std::string{prime::to_string(*code)});
  m.attr("codes") = codes;

  py::class_<Held, std::shared_ptr<Held>>(m, "Held", py::buffer_protocol())
      .def_buffer([](Held& h) {
        check_own(&h);
        const auto bytes = h.sample.value.bytes();
        return py::buffer_info(const_cast<std::byte*>(bytes.data()), 1, py::format_descriptor<std::uint8_t>::format(), 1,
                               {static_cast<py::ssize_t>(bytes.size())}, {1}, /*readonly=*/true);
      })
      .def_property_readonly("sequence", [](const Held& h) { return h.sample.value.sequence(); })
      .def_property_readonly("stamp", [](const Held& h) { return seconds_of(h.sample.stamp); })
      .def_property_readonly("size", [](const Held& h) { return h.sample.value.bytes().size(); });

  py::class_<Subscriber, Handle<Subscriber>>(m, "Subscriber")
      .def("read", &Subscriber::read, py::arg("timeout") = py::none())
      .def_property_readonly("name", [](const Subscriber& s) { return s.source.name(); })
      .def("try_read", &Subscriber::try_read)
      .def("read_batch", &Subscriber::read_batch, py::arg("max"), py::arg("timeout") = py::none())
      .def_property_readonly("lost", [](Subscriber& s) {
        return without_gil([&] {
          std::scoped_lock lock{s.mutex};
          return s.own().lost();
        });
      });

  py::class_<SyncReader, Handle<SyncReader>>(m, "Sync").def("read", &SyncReader::read, py::arg("timeout") = py::none());
  m.def(
      "sync",
      [](const std::string& kind, double tolerance, std::size_t depth, std::optional<double> max_span,
         const std::vector<double>& min_interval, double age_penalty, int trigger, const std::vector<Subscriber*>& inputs) {
        const auto policy = policy_of(kind, tolerance, depth, max_span, min_interval, age_penalty, trigger);
        if (std::ranges::any_of(inputs, [](const Subscriber* s) { return s == nullptr; }))
          throw prime::Failure{{prime::Errc::invalid_argument, "a sync takes subscribers"}};
        if (inputs.size() < 2 || inputs.size() > prime::kMaxSyncInputs)
          throw prime::Failure{{prime::Errc::invalid_argument, "a sync takes 2 to " + std::to_string(prime::kMaxSyncInputs) +
                                                                   " subscribers, not " + std::to_string(inputs.size())}};
        for (auto* s : inputs) {
          if (std::ranges::count(inputs, s) > 1)
            throw prime::Failure{{prime::Errc::invalid_argument, "the subscriber of '" + s->source.name() + "' is given twice"}};
          s->own();  // not given to another sync: checked before any is given
        }
        std::vector<shm::Subscription<shm::Bytes>> sources;
        for (auto* s : inputs) sources.push_back(s->source);
        auto reader = make_handle<SyncReader>(policy, std::move(sources));  // may still refuse: nothing given yet
        for (auto* s : inputs) s->give();
        return reader;
      },
      py::arg("kind"), py::arg("tolerance"), py::arg("depth"), py::arg("max_span"), py::arg("min_interval"),
      py::arg("age_penalty"), py::arg("trigger"), py::arg("inputs"), py::keep_alive<0, 8>());

  py::class_<Publisher, Handle<Publisher>>(m, "Publisher")
      .def("publish", &Publisher::publish, py::arg("data"), py::arg("stamp") = py::none())
      .def(
          "loan",
          [](Publisher& p, std::size_t size) {
            check_own(&p);
            auto got = p.use([&](auto& publisher) {  // a `block` topic may make it wait for room
              return std::optional{publisher.loan(size)};
            });
            if (!*got) throw prime::Failure{got->error()};
            return make_handle<LoanedMessage>(&p, std::move(**got));
          },
          py::arg("size"), py::keep_alive<0, 1>());

  py::class_<LoanedMessage, Handle<LoanedMessage>>(m, "Loan", py::buffer_protocol())
      .def_buffer([](LoanedMessage& l) {
        check_own(&l);
        if (!l.loan) throw py::buffer_error("this loan was published already");
        const auto bytes = l.loan->bytes();
        return py::buffer_info(bytes.data(), 1, py::format_descriptor<std::uint8_t>::format(), 1,
                               {static_cast<py::ssize_t>(bytes.size())}, {1}, /*readonly=*/false);
      })
      .def("publish", &LoanedMessage::publish, py::arg("stamp") = py::none());

  py::class_<Client, Handle<Client>>(m, "Client").def("call", &Client::call, py::arg("request"));

  py::class_<shm::Core::RawType>(m, "Type")
      .def(py::init(&type_of), py::arg("name"), py::arg("size"), py::arg("alignment"), py::arg("layout"), py::arg("schema"))
      .def_static("raw", [] { return shm::Core::RawType{prime::Fingerprint::of<shm::Bytes>(), ""}; })
      .def_property_readonly("described", [](const shm::Core::RawType& t) { return t.type.describe(); })
      .def_property_readonly("hash", [](const shm::Core::RawType& t) { return t.type.hash; })
      .def_readonly("schema", &shm::Core::RawType::schema);

  py::class_<shm::Core, Handle<shm::Core>>(m, "Core")
      .def(py::init([](const std::string& domain, const std::string& participant) {
             return make_handle<shm::Core>(domain, shm::DomainOptions{.participant = participant});
           }),
           py::arg("domain"), py::arg("participant") = "")
      .def_property_readonly("domain", &shm::Core::domain)
      .def(
          "subscribe",
          [](shm::Core& core, const std::string& name, std::size_t history, double spin) {
            check_own(&core);
            const auto micros = std::chrono::duration_cast<std::chrono::microseconds>(duration_of(spin, "a spin"));
            return make_handle<Subscriber>(core.raw_subscription(name, {.history = history, .spin = micros}));
          },
          py::arg("name"), py::arg("history") = 0, py::arg("spin") = 50e-6, py::keep_alive<0, 1>())
      .def(
          "subscribe",
          [](shm::Core& core, const std::string& name, std::size_t history, double spin, const shm::Core::RawType& type,
             std::size_t capacity, bool block, std::size_t max_message_size, std::size_t max_subscribers) {
            check_own(&core);
            const auto micros = std::chrono::duration_cast<std::chrono::microseconds>(duration_of(spin, "a spin"));
            const shm::TopicQos topic{.capacity = capacity,
                                      .max_message_size = max_message_size,
                                      .overflow = block ? prime::Overflow::block : prime::Overflow::drop_oldest,
                                      .max_subscribers = max_subscribers};
            return make_handle<Subscriber>(core.raw_subscription(name, type, topic, {.history = history, .spin = micros}));
          },
          py::arg("name"), py::arg("history"), py::arg("spin"), py::arg("type"), py::arg("capacity"), py::arg("block"),
          py::arg("max_message_size"), py::arg("max_subscribers"), py::keep_alive<0, 1>())
      .def(
          "publisher",
          [](shm::Core& core, const std::string& name) {
            check_own(&core);
            return make_handle<Publisher>(core.raw_publisher(name));
          },
          py::arg("name"), py::keep_alive<0, 1>())
      .def(
          "publisher",
          [](shm::Core& core, const std::string& name, const shm::Core::RawType& type, std::size_t capacity, bool block,
             double block_timeout, std::size_t max_message_size, std::size_t max_subscribers) {
            check_own(&core);
            check_own(&core);
            const shm::TopicQos qos{.capacity = capacity,
                                    .max_message_size = max_message_size,
                                    .overflow = block ? prime::Overflow::block : prime::Overflow::drop_oldest,
                                    .block_timeout = call_timeout(block_timeout),
                                    .max_subscribers = max_subscribers};
            return make_handle<Publisher>(core.raw_publisher(name, type.type, type.schema, qos));
          },
          py::arg("name"), py::arg("type"), py::arg("capacity"), py::arg("block"), py::arg("block_timeout"),
          py::arg("max_message_size"), py::arg("max_subscribers"), py::keep_alive<0, 1>())
      .def(
          "serve",
          [](shm::Core& core, const std::string& name, const shm::Core::RawType& request, const shm::Core::RawType& reply,
             py::function fn, std::size_t workers, double timeout, std::size_t max_request_size, std::size_t max_reply_size) {
            check_own(&core);
            check_own(&core);
            auto function = std::make_shared<ServiceFunction>(core, std::move(fn));
            core.raw_serve(name, request, reply,
                           [function](const std::byte* in, std::size_t size, std::byte* out, std::size_t capacity) {
                             return (*function)(in, size, out, capacity);
                           },
                           {.workers = workers,
                            .timeout = call_timeout(timeout),
                            .max_request_size = max_request_size,
                            .max_reply_size = max_reply_size});
          },
          py::arg("name"), py::arg("request"), py::arg("reply"), py::arg("fn"), py::arg("workers"), py::arg("timeout"),
          py::arg("max_request_size"), py::arg("max_reply_size"))
      .def("stop", &stop)
      .def(
          "client",
          [](shm::Core& core, const std::string& name, std::optional<double> timeout) {
            check_own(&core);
            return make_handle<Client>(Client{core.raw_chain(name, {.timeout = call_timeout(timeout)})});
          },
          py::arg("name"), py::arg("timeout") = py::none(), py::keep_alive<0, 1>())
      .def("topic", [](shm::Core& core, const std::string& name) -> py::object {
            check_own(&core);
        for (const auto& t : core.registry().topics)
          if (t.name == name) return topic_info(t);
        return py::none();
      })
      .def("service", [](shm::Core& core, const std::string& name) -> py::object {
            check_own(&core);
        for (const auto& s : core.registry().services)
          if (s.name == name) {
            py::dict d;
            d["name"] = s.name;
            d["request_type"] = s.request_type;
            d["reply_type"] = s.reply_type;
            d["request_schema"] = s.request_schema;
            d["reply_schema"] = s.reply_schema;
            const auto raw = prime::Fingerprint::of<shm::Bytes>().describe();
            d["request_raw"] = s.request_type == raw;
            d["reply_raw"] = s.reply_type == raw;
            return d;
          }
        return py::none();
      });
}
