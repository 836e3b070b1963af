#pragma once

#include <cstddef>
#include <expected>
#include <functional>
#include <memory>
#include <vector>

#include "prime/logic/error.hpp"

namespace prime::shm::detail {

// What the typed service headers hand to libprime_shm: a client's route
// and its calls, a server's handler.

// A client's hold on one service: its segment, its client slot, the server
// it last saw alive. Opaque here; compiled in libprime_shm (src/caller.cpp).
class Binding;

// The services one call goes through: one, or several linked (each one's
// output goes straight into the next one's cell).
using Route = std::vector<std::shared_ptr<Binding>>;

// Writes a request: its bytes at `to` (room for `capacity`); returns its size.
using RequestWriter = std::function<std::size_t(std::byte* to, std::size_t capacity)>;
// Reads an answer where it lies: its bytes and their count.
using ReplyReader = std::function<void(const std::byte* from, std::size_t size)>;

// Asked on the calling thread each time a call has slept a slice (at most
// 25 ms) with no answer: true gives the call up (Errc::stopped).
using GiveUp = std::function<bool()>;

// One call through `route`: the caller sends once and waits once, for the
// last service. `read` takes the answer in place. `posted`: no answer is
// waited for. `give_up`, if any: see GiveUp.
std::expected<void, Error> call(const Route& route, const RequestWriter& write, const ReplyReader& read, bool posted,
                                const GiveUp& give_up = {});

// `first` then `second`, as one route. Throws Failure: Errc::type_mismatch
// when the last service of `first` gives what the first of `second` does
// not take (Bytes takes anything: tools' raw chains), Errc::invalid_argument
// past the hops one linked call may go through.
Route linked(const Route& first, const Route& second);

// A server's block, erased: runs it on a request of `size` bytes at
// `request` and writes the answer at `out`, which has room for `capacity`
// bytes; returns the answer's size. What it throws is the call's error.
using Handler = std::function<std::size_t(const std::byte* request, std::size_t size, std::byte* out, std::size_t capacity)>;

}  // namespace prime::shm::detail
