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

Clock::time_point deadline_after(std::optional<double> seconds) {
  if (!seconds) return Clock::time_point::max();
  if (*seconds < 0) throw prime::Failure{{prime::Errc::invalid_argument, "a timeout cannot be negative"}};
  return Clock::now() + std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>{*seconds});
}

std::chrono::milliseconds milliseconds(std::optional<double> seconds) {
  if (!seconds) return std::chrono::milliseconds{0};
  if (*seconds < 0) throw prime::Failure{{prime::Errc::invalid_argument, "a timeout cannot be negative"}};
  return std::chrono::milliseconds{static_cast<std::int64_t>(*seconds * 1000.0 + 0.5)};
}

double seconds_of(Clock::time_point t) { return std::chrono::duration<double>{t.time_since_epoch()}.count(); }

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
      std::optional<std::expected<prime::Sample<shm::View<shm::Bytes>>, prime::Error>> got;
      {
        py::gil_scoped_release release;
        std::scoped_lock lock{mutex};
        got.emplace(reader.read_until(std::min(deadline, Clock::now() + kSignalCheck)));
      }
      if (*got) return std::make_shared<Held>(Held{std::move(**got)});
      if (got->error().code != prime::Errc::timeout || Clock::now() >= deadline) throw prime::Failure{got->error()};
      if (PyErr_CheckSignals() != 0) throw py::error_already_set();
    }
  }

  std::optional<std::shared_ptr<Held>> try_read() {
    std::optional<prime::Sample<shm::View<shm::Bytes>>> got;
    {
      py::gil_scoped_release release;
      std::scoped_lock lock{mutex};
      got = reader.try_read();
    }
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
    const auto when = stamp ? Clock::time_point{std::chrono::duration_cast<Clock::duration>(std::chrono::duration<double>{*stamp})}
                            : Clock::now();
    const std::span bytes{static_cast<const std::byte*>(info.ptr), static_cast<std::size_t>(info.size * info.itemsize)};
    std::expected<void, prime::Error> sent;
    {
      py::gil_scoped_release release;  // a `block` topic may make it wait for room
      std::scoped_lock lock{mutex};
      sent = publisher.publish(bytes, when);
    }
    if (!sent) throw prime::Failure{sent.error()};
  }
};

// A message loaned in the topic's ring, written in place through its
// exported (writable) bytes, then published or given back. prime/shm.py
// publishes only once no array over the bytes lives.
struct LoanedMessage {
  Publisher* publisher;
  std::optional<shm::Loan<shm::Bytes>> loan;

  void publish(std::optional<double> stamp) {
    if (!loan) throw prime::Failure{{prime::Errc::invalid_argument, "this loan was published or given back already"}};
    std::scoped_lock lock{publisher->mutex};
    std::move(*loan).publish(stamp ? Clock::time_point{std::chrono::duration_cast<Clock::duration>(
                                         std::chrono::duration<double>{*stamp})}
                                   : Clock::now());
    loan.reset();
  }

  void give_back() {
    std::scoped_lock lock{publisher->mutex};
    loan.reset();
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
    std::expected<void, prime::Error> done;
    {
      py::gil_scoped_release release;
      done = chain.call_in_place(
          [&](std::span<std::byte> to) {
            std::memcpy(to.data(), info.ptr, std::min(size, to.size()));
            return size;  // over the room: the call fails with too_large
          },
          [&](std::span<const std::byte> from) { reply.assign(reinterpret_cast<const char*>(from.data()), from.size()); });
    }
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
      PyErr_SetObject(type.ptr(), py::make_tuple(code, e.message).ptr());
    }
  });

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
      .def_property_readonly("lost", [](Subscriber& s) { return s.reader.lost(); });

  py::class_<Publisher>(m, "Publisher")
      .def("publish", &Publisher::publish, py::arg("data"), py::arg("stamp") = py::none())
      .def(
          "loan",
          [](Publisher& p, std::size_t size) {
            std::optional<std::expected<shm::Loan<shm::Bytes>, prime::Error>> got;
            {
              py::gil_scoped_release release;  // a `block` topic may make it wait for room
              std::scoped_lock lock{p.mutex};
              got.emplace(p.publisher.loan(size));
            }
            if (!*got) throw prime::Failure{got->error()};
            return std::make_unique<LoanedMessage>(LoanedMessage{&p, std::move(**got)});
          },
          py::arg("size"), py::keep_alive<0, 1>());

  py::class_<LoanedMessage>(m, "Loan", py::buffer_protocol())
      .def_buffer([](LoanedMessage& l) {
        if (!l.loan) throw py::buffer_error("this loan was published or given back already");
        const auto bytes = l.loan->bytes();
        return py::buffer_info(bytes.data(), 1, py::format_descriptor<std::uint8_t>::format(), 1,
                               {static_cast<py::ssize_t>(bytes.size())}, {1}, /*readonly=*/false);
      })
      .def("publish", &LoanedMessage::publish, py::arg("stamp") = py::none())
      .def("give_back", &LoanedMessage::give_back);

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
            const auto micros = std::chrono::microseconds{static_cast<std::int64_t>(spin * 1e6)};
            return std::make_unique<Subscriber>(core.raw_subscribe(name, {.history = history, .spin = micros}));
          },
          py::arg("name"), py::arg("history") = 0, py::arg("spin") = 50e-6, py::keep_alive<0, 1>())
      .def(
          "publisher", [](shm::Core& core, const std::string& name) { return std::make_unique<Publisher>(core.raw_publisher(name)); },
          py::arg("name"), py::keep_alive<0, 1>())
      .def(
          "client",
          [](shm::Core& core, const std::string& name, std::optional<double> timeout) {
            return std::make_unique<Client>(Client{core.raw_chain(name, {.timeout = milliseconds(timeout)})});
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
