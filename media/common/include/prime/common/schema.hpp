#pragma once

#include <array>
#include <cstddef>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <tuple>
#include <type_traits>
#include <utility>

#include "prime/common/bounded_string.hpp"
#include "prime/common/bounded_vector.hpp"

// A message type's description: its fields' names, kinds and offsets, as
// text that travels with a topic or service, so a tool that never saw the
// C++ type (`prime echo`, `prime pub`) can read and write it. Declare it
// once, next to the type, in the type's namespace:
//
//   struct Pose { double x, y, theta; };
//   PRIME_DESCRIBE(Pose, x, y, theta)
//
// Fields may be numbers, bool, char, bounded_string, bounded_vector and
// std::array of those, and other described types. The text, one type:
//
//   type  := "i8" | "i16" | "i32" | "i64" | "u8" | ... | "u64" | "f32" | "f64" | "bool" | "char"
//          | "str" N "@" size_offset "," data_offset              bounded_string<N>
//          | "vec" N "@" size_offset "," data_offset "," stride "(" type ")"   bounded_vector<T, N>
//          | "arr" N "," stride "(" type ")"                       std::array<T, N>
//          | "{" field ("," field)* "}"                            a described struct
//          | "?" size                                             anything else: shown as bytes
//   field := name "@" offset ":" type

namespace prime {

namespace detail {

// What PRIME_DESCRIBE records: the fields' names, as written, and their member pointers.
template <class T, class Members>
struct Description {
  std::string_view names;  // "x, y, theta"
  Members members;         // std::tuple<double T::*, ...>
};

template <class T>
concept HasDescription = requires { prime_describe(static_cast<const T*>(nullptr)); };

template <class T>
struct is_bounded_string : std::false_type {};
template <std::size_t N>
struct is_bounded_string<bounded_string<N>> : std::true_type {};
template <class T>
struct is_bounded_vector : std::false_type {};
template <class T, std::size_t N>
struct is_bounded_vector<bounded_vector<T, N>> : std::true_type {};
template <class T>
struct is_std_array : std::false_type {};
template <class T, std::size_t N>
struct is_std_array<std::array<T, N>> : std::true_type {};

inline std::string_view next_name(std::string_view& names) {
  const auto comma = names.find(',');
  auto name = names.substr(0, comma);
  names = comma == std::string_view::npos ? std::string_view{} : names.substr(comma + 1);
  while (!name.empty() && name.front() == ' ') name.remove_prefix(1);
  while (!name.empty() && name.back() == ' ') name.remove_suffix(1);
  return name;
}

}  // namespace detail

template <class T>
std::string schema_of();

namespace detail {

template <class T, class Tuple, std::size_t... I>
std::string fields_of(std::string_view names, const Tuple& members, std::index_sequence<I...>) {
  // Offsets are read off storage the size of T, never constructed: T may be
  // megabytes, too large for the stack.
  std::allocator<T> allocator;
  T* probe = allocator.allocate(1);
  const auto* base = reinterpret_cast<const std::byte*>(probe);
  std::string text = "{";
  (
      [&] {
        const auto& member = std::get<I>(members);
        using M = std::remove_cvref_t<decltype(probe->*member)>;
        const auto offset = reinterpret_cast<const std::byte*>(&(probe->*member)) - base;
        if (I != 0) text += ",";
        text += std::string{next_name(names)} + "@" + std::to_string(offset) + ":" + schema_of<M>();
      }(),
      ...);
  allocator.deallocate(probe, 1);
  return text + "}";
}

}  // namespace detail

// The description of T as text (see above); "?<size>" when T has none.
template <class T>
std::string schema_of() {
  if constexpr (std::is_same_v<T, bool>) return "bool";
  else if constexpr (std::is_same_v<T, char>) return "char";
  else if constexpr (std::is_integral_v<T>) return (std::is_signed_v<T> ? "i" : "u") + std::to_string(8 * sizeof(T));
  else if constexpr (std::is_same_v<T, float>) return "f32";
  else if constexpr (std::is_same_v<T, double>) return "f64";
  else if constexpr (detail::is_bounded_string<T>::value)
    return "str" + std::to_string(T::capacity()) + "@" + std::to_string(T::size_offset()) + "," +
           std::to_string(T::data_offset());
  else if constexpr (detail::is_bounded_vector<T>::value)
    return "vec" + std::to_string(T::capacity()) + "@" + std::to_string(T::size_offset()) + "," +
           std::to_string(T::data_offset()) + "," + std::to_string(sizeof(typename T::value_type)) + "(" +
           schema_of<typename T::value_type>() + ")";
  else if constexpr (detail::is_std_array<T>::value)
    return "arr" + std::to_string(std::tuple_size_v<T>) + "," + std::to_string(sizeof(typename T::value_type)) + "(" +
           schema_of<typename T::value_type>() + ")";
  else if constexpr (detail::HasDescription<T>) {
    const auto description = prime_describe(static_cast<const T*>(nullptr));
    return detail::fields_of<T>(description.names, description.members,
                                std::make_index_sequence<std::tuple_size_v<decltype(description.members)>>{});
  } else {
    return "?" + std::to_string(sizeof(T));
  }
}

}  // namespace prime

// PRIME_DESCRIBE(Type, field, field, ...): up to 24 fields.
#define PRIME_DESCRIBE_MEMBER_(Type, f) &Type::f
#define PRIME_DESCRIBE_1_(T, a) PRIME_DESCRIBE_MEMBER_(T, a)
#define PRIME_DESCRIBE_2_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_1_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_3_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_2_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_4_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_3_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_5_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_4_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_6_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_5_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_7_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_6_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_8_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_7_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_9_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_8_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_10_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_9_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_11_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_10_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_12_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_11_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_13_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_12_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_14_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_13_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_15_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_14_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_16_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_15_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_17_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_16_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_18_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_17_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_19_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_18_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_20_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_19_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_21_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_20_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_22_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_21_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_23_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_22_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_24_(T, a, ...) PRIME_DESCRIBE_MEMBER_(T, a), PRIME_DESCRIBE_23_(T, __VA_ARGS__)
#define PRIME_DESCRIBE_COUNT_(_1, _2, _3, _4, _5, _6, _7, _8, _9, _10, _11, _12, _13, _14, _15, _16, _17, _18, _19, \
                              _20, _21, _22, _23, _24, N, ...)                                                        \
  N
#define PRIME_DESCRIBE_PICK_(N) PRIME_DESCRIBE_##N##_
#define PRIME_DESCRIBE_APPLY_(N, T, ...) PRIME_DESCRIBE_PICK_(N)(T, __VA_ARGS__)
#define PRIME_DESCRIBE_MEMBERS_(T, ...)                                                                              \
  PRIME_DESCRIBE_APPLY_(PRIME_DESCRIBE_COUNT_(__VA_ARGS__, 24, 23, 22, 21, 20, 19, 18, 17, 16, 15, 14, 13, 12, 11, 10, \
                                              9, 8, 7, 6, 5, 4, 3, 2, 1),                                            \
                        T, __VA_ARGS__)

#define PRIME_DESCRIBE(Type, ...)                                                                              \
  [[maybe_unused]] inline auto prime_describe(const Type*) {                                                     \
    auto members = std::make_tuple(PRIME_DESCRIBE_MEMBERS_(Type, __VA_ARGS__));                                  \
    return ::prime::detail::Description<Type, decltype(members)>{#__VA_ARGS__, members};                           \
  }
