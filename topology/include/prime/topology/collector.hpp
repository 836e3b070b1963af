#pragma once

#include <chrono>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/reader.hpp"
#include "prime/logic/sample.hpp"
#include "prime/logic/token.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"

namespace prime {

// Asks a collector for every unread value instead of the latest one.
struct AllUnread {};
inline constexpr AllUnread all_unread{};
// Asks a collector for nothing, rather than an error, before the first value.
struct OrNothing {};
inline constexpr OrNothing or_nothing{};
// Asks a collector to wait, up to `wait`, for the first value.
struct FirstWithin {
  Clock::duration wait;
};
constexpr FirstWithin first_within(Clock::duration wait) { return {wait}; }

namespace detail {

// A reader shared by every copy of a collector chain; the chain may be called
// from several threads.
template <class T>
struct SharedReader {
  explicit SharedReader(Reader<T> r, std::string n) : reader{std::move(r)}, name{std::move(n)} {}
  std::mutex mutex;
  Reader<T> reader;
  const std::string name;
  std::optional<T> waited_for;  // the first value, when a call waited for it (it stays the newest until another comes)
};

template <class T>
struct Latest {
  std::shared_ptr<SharedReader<T>> input;

  T operator()(Token) const {
    std::scoped_lock lock{input->mutex};
    auto sample = input->reader.latest();
    if (!sample) throw Failure{{Errc::no_data, "collector of '" + input->name + "': nothing published yet"}};
    return std::move(sample->value);
  }
};

template <class T>
struct LatestOrNothing {
  std::shared_ptr<SharedReader<T>> input;

  std::optional<T> operator()(Token) const {
    std::scoped_lock lock{input->mutex};
    auto sample = input->reader.latest();
    if (!sample) return std::nullopt;
    return std::move(sample->value);
  }
};

template <class T>
struct LatestWaiting {
  std::shared_ptr<SharedReader<T>> input;
  Clock::duration wait;

  T operator()(Token) const {
    std::scoped_lock lock{input->mutex};
    if (auto sample = input->reader.latest()) {
      input->waited_for.reset();
      return std::move(sample->value);
    }
    if (input->waited_for) return *input->waited_for;
    auto first = input->reader.read_for(wait);
    if (!first)
      throw Failure{{first.error().code == Errc::timeout ? Errc::no_data : first.error().code,
                     "collector of '" + input->name + "': nothing published within " +
                         std::to_string(std::chrono::duration_cast<std::chrono::milliseconds>(wait).count()) + " ms"}};
    input->waited_for = std::move(first->value);
    return *input->waited_for;
  }
};

template <class T>
struct Unread {
  std::shared_ptr<SharedReader<T>> input;

  std::vector<T> operator()(Token) const {
    std::scoped_lock lock{input->mutex};
    std::vector<T> values;
    while (auto sample = input->reader.try_read()) values.push_back(std::move(sample->value));
    return values;
  }
};

template <class T, template <class> class Collect, Medium M, Source S, class... Options>
auto make_collector(M& core, const S& source, std::string name, Options... options) {
  Graph graph = Graph::sequence(source.graph(), Graph::node(std::move(name), "collector", std::string{core.medium()}));
  auto input = std::make_shared<SharedReader<T>>(source.subscribe(), source.name());
  return core.template chain<Token>(Collect<T>{std::move(input), options...}, std::move(graph));
}

}  // namespace detail

// Chain<Token, T>: where asynchronous data meets a synchronous chain. Each call
// gives the newest value the source has published (the same one again if
// nothing newer came); before the first value it throws Errc::no_data.
// Starts no worker.
template <Medium M, Source S>
[[nodiscard]] auto collector(M& core, const S& source, std::string name = "collector") {
  return detail::make_collector<typename S::value_type, detail::Latest>(core, source, std::move(name));
}

// Chain<Token, std::optional<T>>: the newest value, or nothing before the
// first: "not yet" is a value, not an error.
template <Medium M, Source S>
[[nodiscard]] auto collector(M& core, const S& source, OrNothing, std::string name = "collector") {
  return detail::make_collector<typename S::value_type, detail::LatestOrNothing>(core, source, std::move(name));
}

// Chain<Token, T>: the newest value; before the first, a call waits up to
// `first.wait` for it, and throws Errc::no_data only if none comes.
template <Medium M, Source S>
[[nodiscard]] auto collector(M& core, const S& source, FirstWithin first, std::string name = "collector") {
  return detail::make_collector<typename S::value_type, detail::LatestWaiting>(core, source, std::move(name), first.wait);
}

// Chain<Token, std::vector<T>>: each call gives every value published since the
// last call, oldest first (less what the buffer dropped).
template <Medium M, Source S>
[[nodiscard]] auto collector(M& core, const S& source, AllUnread, std::string name = "collector") {
  return detail::make_collector<typename S::value_type, detail::Unread>(core, source, std::move(name));
}

}  // namespace prime
