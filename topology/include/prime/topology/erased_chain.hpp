#pragma once

#include <functional>
#include <string>
#include <memory>
#include <type_traits>
#include <utility>
#include <vector>

#include "prime/topology/chain_factory.hpp"
#include "prime/topology/concepts.hpp"
#include "prime/topology/graph.hpp"
#include "prime/topology/link.hpp"
#include "prime/topology/runtime.hpp"

namespace prime {

namespace detail::erased {

// The one type-erased piece: a step from In to Out, shared by every chain
// that contains it. Linked steps are themselves a step, so linking never
// copies a block and a chain is built at run time, from a config say.
template <class In, class Out>
class Step {
 public:
  virtual ~Step() = default;
  virtual Out operator()(In in) const = 0;
};

// A step that takes and gives one type also updates a value in place, so a
// sequence of them moves the value into each block and back, no more.
template <class T>
  requires std::is_move_assignable_v<T>
class Step<T, T> {
 public:
  virtual ~Step() = default;
  virtual T operator()(T in) const = 0;
  virtual void update(T& value) const { value = (*this)(std::move(value)); }
};

template <class In, class Out, class F>
class BlockStep final : public Step<In, Out> {
 public:
  explicit BlockStep(F block) : block_{std::move(block)} {}
  Out operator()(In in) const override { return std::invoke(block_, std::move(in)); }
  // Step<T, T>::update, where In and Out are one type (never used otherwise).
  void update(In& value) const { value = std::invoke(block_, std::move(value)); }

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

// Steps that all take and give T, held flat: one indirect call per step and
// no recursion, however long a chain grows at run time.
template <class T>
class SequenceStep final : public Step<T, T> {
 public:
  using Steps = std::vector<std::shared_ptr<const Step<T, T>>>;

  explicit SequenceStep(Steps steps) : steps_{std::move(steps)} {}
  T operator()(T value) const override {
    update(value);
    return value;
  }
  void update(T& value) const override {
    for (const auto& step : steps_) step->update(value);
  }

  // The steps of `step`, looking inside a sequence rather than nesting it.
  static void append(Steps& to, const std::shared_ptr<const Step<T, T>>& step) {
    if (auto sequence = std::dynamic_pointer_cast<const SequenceStep>(step))
      to.insert(to.end(), sequence->steps_.begin(), sequence->steps_.end());
    else
      to.push_back(step);
  }

 private:
  Steps steps_;
};

template <class In, class Mid, class Out>
std::shared_ptr<const Step<In, Out>> linked(std::shared_ptr<const Step<In, Mid>> first,
                                            std::shared_ptr<const Step<Mid, Out>> second) {
  if constexpr (std::is_same_v<In, Mid> && std::is_same_v<Mid, Out> && std::is_move_assignable_v<In>) {
    typename SequenceStep<In>::Steps steps;
    SequenceStep<In>::append(steps, first);
    SequenceStep<In>::append(steps, second);
    return std::make_shared<const SequenceStep<In>>(std::move(steps));
  } else {
    return std::make_shared<const LinkedStep<In, Mid, Out>>(std::move(first), std::move(second));
  }
}

}  // namespace detail::erased

// The one type-erased chain, for media that compose at run time (Liberty)
// or run local blocks beside what they carry (Shm). Its type says only what goes in and what comes out: one indirect
// call per block, where the blocks all take and give one type; two where the
// type changes from block to block. Copies share the blocks.
//
// Thread-safe to call from several threads when the blocks are.
template <class In, class Out>
class ErasedChain {
 public:
  using input_type = In;
  using output_type = Out;

  ErasedChain(std::shared_ptr<const detail::erased::Step<In, Out>> step, Graph graph)
      : step_{std::move(step)}, graph_{std::make_shared<const Graph>(std::move(graph))} {}

  Out operator()(In in) const { return (*step_)(std::move(in)); }
  [[nodiscard]] const Graph& graph() const noexcept { return *graph_; }
  [[nodiscard]] const std::shared_ptr<const detail::erased::Step<In, Out>>& step() const noexcept { return step_; }

 private:
  std::shared_ptr<const detail::erased::Step<In, Out>> step_;
  std::shared_ptr<const Graph> graph_;
};

static_assert(Chain<ErasedChain<int, double>>);

template <class In, class Mid, class Out>
[[nodiscard]] ErasedChain<In, Out> link(const ErasedChain<In, Mid>& first, const ErasedChain<Mid, Out>& second) {
  return {detail::erased::linked<In, Mid, Out>(first.step(), second.step()), Graph::sequence(first.graph(), second.graph())};
}


// A core whose chains are erased chains of its medium: Liberty's, and the
// local chains of media that carry sources between processes.
class ErasedChainRuntime : public Runtime, public ChainFactory<ErasedChainRuntime> {
 public:
  using Runtime::Runtime;
  using ChainFactory<ErasedChainRuntime>::chain;

  // A chain of one block (or of a chain of another medium, adopted whole).
  template <class In = detail::Deduce, int&... ExplicitArgumentBarrier, class F>
  [[nodiscard]] auto chain(F block, Graph graph) {
    using I = chain_input_t<In, F>;
    static_assert(Block<F, I>, "prime: a block must be callable as Out(In) and return a value");
    using Out = block_output_t<F, I>;
    return ErasedChain<I, Out>{std::make_shared<const detail::erased::BlockStep<I, Out, F>>(std::move(block)),
                               std::move(graph)};
  }
};

}  // namespace prime
