#pragma once

#include <memory>
#include <mutex>
#include <string>
#include <utility>
#include <vector>

#include "prime/logic/error.hpp"
#include "prime/logic/reader.hpp"
#include "prime/logic/token.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"

namespace prime {

// Asks a collector for every unread value instead of the latest one.
struct AllUnread {};
inline constexpr AllUnread all_unread{};

namespace detail {

// A reader shared by every copy of a collector chain; the chain may be called
// from several threads.
template <class T>
struct SharedReader {
  explicit SharedReader(Reader<T> r, std::string n) : reader{std::move(r)}, name{std::move(n)} {}
  std::mutex mutex;
  Reader<T> reader;
  const std::string name;
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
struct Unread {
  std::shared_ptr<SharedReader<T>> input;

  std::vector<T> operator()(Token) const {
    std::scoped_lock lock{input->mutex};
    std::vector<T> values;
    while (auto sample = input->reader.try_read()) values.push_back(std::move(sample->value));
    return values;
  }
};

template <class T, template <class> class Collect, Medium M, Source S>
auto make_collector(M& core, const S& source, std::string name) {
  Graph graph = Graph::sequence(source.graph(), Graph::node(std::move(name), "collector", std::string{core.medium()}));
  auto input = std::make_shared<SharedReader<T>>(source.subscribe(), source.name());
  return core.template chain<Token>(Collect<T>{std::move(input)}, std::move(graph));
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

// Chain<Token, std::vector<T>>: each call gives every value published since the
// last call, oldest first (less what the buffer dropped).
template <Medium M, Source S>
[[nodiscard]] auto collector(M& core, const S& source, AllUnread, std::string name = "collector") {
  return detail::make_collector<typename S::value_type, detail::Unread>(core, source, std::move(name));
}

}  // namespace prime
