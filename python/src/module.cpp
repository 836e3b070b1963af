// prime._prime: the Shm medium for Python, over its run-time-typed handles
// (Core::raw_subscribe, raw_publisher, raw_chain). A sample is handed to
// Python as an object that holds its View and exports its bytes, read-only,
// in place in shared memory; numpy wraps them with no copy (prime/shm.py),
// and the sample stays held while any array made from it lives.
#include <pybind11/pybind11.h>
#include <pybind11/stl.h>

#include <Python.h>

#include <algorithm>
#include <chrono>
#include <cstring>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>

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

// A sample taken from a topic: its bytes stay held in the ring (counted in
// the subscriber's max_held) until this object is gone.
struct Held {
  prime::Sample<shm::View<shm::Bytes>> sample;
};

// One subscriber; reads are serialised (a Reader is read by one thread at a time).
struct Subscriber {
  prime::Reader<shm::View<shm::Bytes>> reader;
  std::mutex mutex;

  std::shared_ptr<Held> read(std::optional<double> timeout) {
    const auto deadline = deadline_after(timeout);
    while (true) {
      auto got = without_gil([&] {
        std::scoped_lock lock{mutex};
        return std::optional{reader.read_until(std::min(deadline, Clock::now() + kSignalCheck))};
      });
      if (*got) return std::make_shared<Held>(Held{std::move(**got)});
      // A slice's end is not the caller's: nothing yet, or no room to hold
      // another sample yet (one held elsewhere may be released meanwhile).
      const auto code = got->error().code;
      if ((code != prime::Errc::timeout && code != prime::Errc::held_limit) || Clock::now() >= deadline)
        throw prime::Failure{got->error()};
      if (PyErr_CheckSignals() != 0) throw py::error_already_set();
    }
  }

  std::optional<std::shared_ptr<Held>> try_read() {
    auto got = without_gil([&] {
      std::scoped_lock lock{mutex};
      return reader.try_read();
    });
    if (!got) return std::nullopt;
    return std::make_shared<Held>(Held{std::move(*got)});
  }
};

struct Publisher {
  shm::Publisher<shm::Bytes> publisher;
  std::mutex mutex;

  void publish(const py::buffer& data, std::optional<double> stamp) {
    const auto info = data.request();
    if (!PyBuffer_IsContiguous(info.view(), 'C'))
      throw prime::Failure{{prime::Errc::invalid_argument, "a message must be one contiguous block of bytes"}};
    const auto when = stamp_of(stamp);
    const std::span bytes{static_cast<const std::byte*>(info.ptr), static_cast<std::size_t>(info.size * info.itemsize)};
    const auto sent = without_gil([&] {  // a `block` topic may make it wait for room
      std::scoped_lock lock{mutex};
      return publisher.publish(bytes, when);
    });
    if (!sent) throw prime::Failure{sent.error()};
  }
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
  // With the GIL held: whoever holds the publisher's lock never waits for
  // the GIL (every other taker releases it first), so this waits at most
  // for that one's publish or loan.
  ~LoanedMessage() {
    if (!loan) return;
    std::scoped_lock lock{publisher->mutex};
    loan.reset();
  }

  void publish(std::optional<double> stamp) {
    if (!loan) throw prime::Failure{{prime::Errc::invalid_argument, "this loan was published already"}};
    const auto when = stamp_of(stamp);
    without_gil([&] {
      std::scoped_lock lock{publisher->mutex};
      std::move(*loan).publish(when);
      loan.reset();
      return true;
    });
  }
};

struct Client {
  shm::ServiceChain<shm::Bytes, shm::Bytes> chain;

  py::bytes call(const py::buffer& request) const {
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
          [&](std::span<const std::byte> from) { reply.assign(reinterpret_cast<const char*>(from.data()), from.size()); });
    });
    if (!done) throw prime::Failure{done.error()};
    return py::bytes{reply};
  }
};

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
        const auto bytes = h.sample.value.bytes();
        return py::buffer_info(const_cast<std::byte*>(bytes.data()), 1, py::format_descriptor<std::uint8_t>::format(), 1,
                               {static_cast<py::ssize_t>(bytes.size())}, {1}, /*readonly=*/true);
      })
      .def_property_readonly("sequence", [](const Held& h) { return h.sample.value.sequence(); })
      .def_property_readonly("stamp", [](const Held& h) { return seconds_of(h.sample.stamp); })
      .def_property_readonly("size", [](const Held& h) { return h.sample.value.bytes().size(); });

  py::class_<Subscriber>(m, "Subscriber")
      .def("read", &Subscriber::read, py::arg("timeout") = py::none())
      .def("try_read", &Subscriber::try_read)
      .def_property_readonly("lost", [](Subscriber& s) {
        return without_gil([&] {
          std::scoped_lock lock{s.mutex};
          return s.reader.lost();
        });
      });

  py::class_<Publisher>(m, "Publisher")
      .def("publish", &Publisher::publish, py::arg("data"), py::arg("stamp") = py::none())
      .def(
          "loan",
          [](Publisher& p, std::size_t size) {
            auto got = without_gil([&] {  // a `block` topic may make it wait for room
              std::scoped_lock lock{p.mutex};
              return std::optional{p.publisher.loan(size)};
            });
            if (!*got) throw prime::Failure{got->error()};
            return std::make_unique<LoanedMessage>(&p, std::move(**got));
          },
          py::arg("size"), py::keep_alive<0, 1>());

  py::class_<LoanedMessage>(m, "Loan", py::buffer_protocol())
      .def_buffer([](LoanedMessage& l) {
        if (!l.loan) throw py::buffer_error("this loan was published already");
        const auto bytes = l.loan->bytes();
        return py::buffer_info(bytes.data(), 1, py::format_descriptor<std::uint8_t>::format(), 1,
                               {static_cast<py::ssize_t>(bytes.size())}, {1}, /*readonly=*/false);
      })
      .def("publish", &LoanedMessage::publish, py::arg("stamp") = py::none());

  py::class_<Client>(m, "Client").def("call", &Client::call, py::arg("request"));

  py::class_<shm::Core>(m, "Core")
      .def(py::init([](const std::string& domain, const std::string& participant) {
             return std::make_unique<shm::Core>(domain, shm::DomainOptions{.participant = participant});
           }),
           py::arg("domain"), py::arg("participant") = "")
      .def_property_readonly("domain", &shm::Core::domain)
      .def(
          "subscribe",
          [](shm::Core& core, const std::string& name, std::size_t history, double spin) {
            const auto micros = std::chrono::duration_cast<std::chrono::microseconds>(duration_of(spin, "a spin"));
            return std::make_unique<Subscriber>(core.raw_subscribe(name, {.history = history, .spin = micros}));
          },
          py::arg("name"), py::arg("history") = 0, py::arg("spin") = 50e-6, py::keep_alive<0, 1>())
      .def(
          "publisher", [](shm::Core& core, const std::string& name) { return std::make_unique<Publisher>(core.raw_publisher(name)); },
          py::arg("name"), py::keep_alive<0, 1>())
      .def(
          "client",
          [](shm::Core& core, const std::string& name, std::optional<double> timeout) {
            return std::make_unique<Client>(Client{core.raw_chain(name, {.timeout = call_timeout(timeout)})});
          },
          py::arg("name"), py::arg("timeout") = py::none(), py::keep_alive<0, 1>())
      .def("topic", [](shm::Core& core, const std::string& name) -> py::object {
        for (const auto& t : core.registry().topics)
          if (t.name == name) return topic_info(t);
        return py::none();
      })
      .def("service", [](shm::Core& core, const std::string& name) -> py::object {
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
