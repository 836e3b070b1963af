#pragma once

#include <concepts>
#include <functional>
#include <type_traits>

namespace prime {

// A block is any callable Out(In): a function, a lambda, a functor. It knows
// nothing of Prime and can be tested on its own.
template <class F, class In>
concept Block = std::invocable<const F&, In> &&
                !std::is_void_v<std::invoke_result_t<const F&, In>>;

template <class F, class In>
using block_output_t = std::remove_cvref_t<std::invoke_result_t<const F&, In>>;

namespace detail {

template <class Signature>
struct signature_input {};
template <class R, class A>
struct signature_input<R(A)> {
  using type = std::remove_cvref_t<A>;
};

// What the one call signature of a callable takes; empty when there is none
// to find (a generic lambda, an overloaded functor).
template <class F>
struct callable_input {};
template <class F>
  requires requires { &F::operator(); }
struct callable_input<F> : callable_input<decltype(&F::operator())> {};
template <class R, class A>
struct callable_input<R (*)(A)> : signature_input<R(A)> {};
template <class R, class A>
struct callable_input<R (*)(A) noexcept> : signature_input<R(A)> {};
template <class R, class A>
struct callable_input<R(A)> : signature_input<R(A)> {};
template <class R, class A>
struct callable_input<R(A) noexcept> : signature_input<R(A)> {};
template <class C, class R, class A>
struct callable_input<R (C::*)(A) const> : signature_input<R(A)> {};
template <class C, class R, class A>
struct callable_input<R (C::*)(A) const noexcept> : signature_input<R(A)> {};
template <class C, class R, class A>
struct callable_input<R (C::*)(A)> : signature_input<R(A)> {};
template <class C, class R, class A>
struct callable_input<R (C::*)(A) noexcept> : signature_input<R(A)> {};

}  // namespace detail

// The input type of a block with exactly one, non-template call signature.
// Generic lambdas and overloaded functors have none: name the input explicitly
// (`core.chain<Scan>(f)`).
template <class F>
using block_input_t = typename detail::callable_input<std::remove_cvref_t<F>>::type;

template <class F>
concept DeducibleBlock = requires { typename block_input_t<F>; };

// A function known at compile time, as a block: `core.chain(prime::fn<&localize>)`.
// A plain `core.chain(localize)` holds a function pointer, which a compiler
// calls indirectly; this holds nothing, so a fused (Radiant) chain inlines it.
template <auto F>
struct Function {
  template <class In>
    requires std::invocable<decltype(F), In>
  [[gnu::always_inline]] constexpr decltype(auto) operator()(In&& in) const {
    if constexpr (std::is_member_pointer_v<decltype(F)>)
      return std::invoke(F, std::forward<In>(in));
    else
      return F(std::forward<In>(in));
  }
};
template <auto F>
inline constexpr Function<F> fn{};

namespace detail {
template <auto F>
struct callable_input<Function<F>> : callable_input<decltype(F)> {};
}  // namespace detail

}  // namespace prime
