#pragma once

#include <cstddef>
#include <memory>
#include <string_view>

namespace prime::optimus::detail {

struct RawReply;  // hiredis's redisReply, seen only inside the library (connection.cpp)

// One node of a reply from the server, read in place: a string, a number,
// an array of nodes, nil, or an error. Lives as long as its Reply.
class ReplyRef {
 public:
  explicit ReplyRef(const RawReply* node) noexcept : node_{node} {}

  [[nodiscard]] bool is_string() const noexcept;  // a bulk string or a status
  [[nodiscard]] bool is_array() const noexcept;
  [[nodiscard]] bool is_integer() const noexcept;
  [[nodiscard]] bool is_nil() const noexcept;
  [[nodiscard]] bool is_error() const noexcept;

  // A string's, a status's or an error's text; empty for the other kinds.
  [[nodiscard]] std::string_view text() const noexcept;
  // An integer's value; 0 for the other kinds.
  [[nodiscard]] long long integer() const noexcept;
  // An array's elements; 0 for the other kinds.
  [[nodiscard]] std::size_t size() const noexcept;
  // Element `i` of an array (i < size()).
  [[nodiscard]] ReplyRef operator[](std::size_t i) const noexcept;

 private:
  const RawReply* node_;
};

// A whole reply, owned: freed when it goes. `reply->is_array()` and
// `(*reply)[0]` read its top node.
class Reply {
 public:
  explicit Reply(RawReply* raw) noexcept : raw_{raw}, top_{raw} {}
  Reply(Reply&& other) noexcept = default;
  Reply& operator=(Reply&& other) noexcept = default;
  ~Reply() = default;

  [[nodiscard]] const ReplyRef& operator*() const noexcept { return top_; }
  [[nodiscard]] const ReplyRef* operator->() const noexcept { return &top_; }

 private:
  struct Free {
    void operator()(RawReply* raw) const noexcept;
  };
  std::unique_ptr<RawReply, Free> raw_;
  ReplyRef top_;
};

// What a reply says, for the few shapes the medium reads.
inline std::string_view text(ReplyRef r) noexcept { return r.text(); }
inline bool is_error(ReplyRef r) noexcept { return r.is_error(); }
inline bool is_nil(ReplyRef r) noexcept { return r.is_nil(); }

}  // namespace prime::optimus::detail
