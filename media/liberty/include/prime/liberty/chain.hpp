#pragma once

#include <functional>
#include <memory>
#include <utility>

#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/link.hpp"

namespace prime::liberty {

namespace detail {

// The one type-erased piece: a step from In to Out, shared by every chain
// that contains it. A linked pair is itself a step, so linking never copies
// what it links and a chain is built at run time, from a config say.
template <class In, class Out>
class Step {
 public:
  virtual ~Step() = default;
  virtual Out operator()(In in) const = 0;
};

template <class In, class Out, class F>
class BlockStep final : public Step<In, Out> {
 public:
  explicit BlockStep(F block) : block_{std::move(block)} {}
  Out operator()(In in) const override { return std::invoke(block_, std::move(in)); }

 private:
  F block_;
};

template <class In, class Mid, class Out>
class LinkedStep final : public Step<In, Out> {
 public:
  LinkedStep(std::shared_ptr<const Step<In, Mid>> first, std::shared_ptr<const Step<Mid, Out>> second)
      : first_{std::move(first)}, second_{std::move(second)} {}
  Out operator()(In in) const override { return (*second_)((*first_)(std::move(in))); }

 private:
  std::shared_ptr<const Step<In, Mid>> first_;
  std::shared_ptr<const Step<Mid, Out>> second_;
};

}  // namespace detail

// A chain whose type says only what goes in and what comes out: one indirect
// call per block. Copies share the block.
//
// Thread-safe to call from several threads when the blocks are.
template <class In, class Out>
class Chain {
 public:
  using input_type = In;
  using output_type = Out;

  Chain(std::shared_ptr<const detail::Step<In, Out>> step, Graph graph)
      : step_{std::move(step)}, graph_{std::make_shared<const Graph>(std::move(graph))} {}

  Out operator()(In in) const { return (*step_)(std::move(in)); }
  [[nodiscard]] const Graph& graph() const noexcept { return *graph_; }
  [[nodiscard]] const std::shared_ptr<const detail::Step<In, Out>>& step() const noexcept { return step_; }

 private:
  std::shared_ptr<const detail::Step<In, Out>> step_;
  std::shared_ptr<const Graph> graph_;
};

static_assert(prime::Chain<Chain<int, double>>);

template <class In, class Mid, class Out>
[[nodiscard]] Chain<In, Out> link(const Chain<In, Mid>& first, const Chain<Mid, Out>& second) {
  return {std::make_shared<const detail::LinkedStep<In, Mid, Out>>(first.step(), second.step()),
          Graph::sequence(first.graph(), second.graph())};
}

using prime::operator|;

}  // namespace prime::liberty
