// UnixSocket: an AF_UNIX SOCK_STREAM socketpair; the child inherits one end.
// Every payload goes through the kernel: the sender writes all `bytes` bytes
// (a sequence number in the first eight, the rest filled once), the receiver
// reads all of them into its own buffer.
//
//   Latency     the parent writes `bytes`, the child reads them and writes
//               `bytes` back: symmetric, the payload crosses twice per round trip.
//   Throughput  the child writes back-to-back messages of `bytes`; the parent
//               reads one per iteration. The socket's buffers (the kernel's
//               defaults) bound what is in flight; a full buffer blocks the
//               writer, so nothing is lost.

#include <sys/socket.h>
#include <sys/time.h>

#include <cerrno>
#include <cstddef>
#include <cstdint>
#include <span>
#include <system_error>
#include <vector>

#include "harness.hpp"
#include "payload.hpp"
#include "unique_fd.hpp"

namespace {

namespace ipc = prime::bench::ipc;

// Blocking calls give up after this long, so a wait can look at the other process.
constexpr timeval kSlice{0, 50'000};

void set_timeouts(int fd) {
  for (const int option : {SO_RCVTIMEO, SO_SNDTIMEO})
    if (::setsockopt(fd, SOL_SOCKET, option, &kSlice, sizeof kSlice) != 0)
      throw std::system_error{errno, std::generic_category(), "setsockopt"};
}

struct SocketPair {
  ipc::UniqueFd parent;
  ipc::UniqueFd child;
};

SocketPair socket_pair() {
  int fds[2];
  if (::socketpair(AF_UNIX, SOCK_STREAM | SOCK_CLOEXEC, 0, fds) != 0)
    throw std::system_error{errno, std::generic_category(), "socketpair"};
  SocketPair pair{ipc::UniqueFd{fds[0]}, ipc::UniqueFd{fds[1]}};
  set_timeouts(pair.parent.get());
  set_timeouts(pair.child.get());
  return pair;
}

template <ipc::Side S>
void write_all(S& side, int fd, std::span<const std::byte> bytes) {
  ipc::Patience<S> patience{side};
  while (!bytes.empty()) {
    const ssize_t n = ::send(fd, bytes.data(), bytes.size(), MSG_NOSIGNAL);
    if (n > 0) bytes = bytes.subspan(static_cast<std::size_t>(n));
    else if (errno == EAGAIN || errno == EWOULDBLOCK) patience.idle();
    else if (errno == EPIPE || errno == ECONNRESET) ipc::hung_up(side, "send");
    else if (errno != EINTR) throw std::system_error{errno, std::generic_category(), "send"};
  }
}

template <ipc::Side S>
void read_all(S& side, int fd, std::span<std::byte> bytes) {
  ipc::Patience<S> patience{side};
  while (!bytes.empty()) {
    const ssize_t n = ::recv(fd, bytes.data(), bytes.size(), 0);
    if (n > 0) bytes = bytes.subspan(static_cast<std::size_t>(n));
    else if (n == 0 || errno == ECONNRESET) ipc::hung_up(side, "recv");
    else if (errno == EAGAIN || errno == EWOULDBLOCK) patience.idle();
    else if (errno != EINTR) throw std::system_error{errno, std::generic_category(), "recv"};
  }
}

void echo(ipc::Child& self) {
  const ipc::UniqueFd socket{self.fd(0)};
  ipc::Payload message{self.bytes()};
  self.ready();
  for (;;) {
    read_all(self, socket.get(), message.bytes());
    write_all(self, socket.get(), message.bytes());
  }
}
const ipc::ChildEntry kEcho{"UnixSocket.echo", echo};

void stream(ipc::Child& self) {
  const ipc::UniqueFd socket{self.fd(0)};
  ipc::Payload message{self.bytes()};
  self.ready();
  for (std::uint64_t seq = 1;; ++seq) {
    self.check();
    message.stamp(seq);
    write_all(self, socket.get(), message.bytes());
  }
}
const ipc::ChildEntry kStream{"UnixSocket.stream", stream};

void BM_Latency_UnixSocket(benchmark::State& state) {
  ipc::run(state, [&](std::size_t bytes) {
    auto sockets = socket_pair();
    ipc::Link child{"UnixSocket.echo", bytes, {sockets.child.get()}};
    sockets.child = ipc::UniqueFd{};
    ipc::Payload out{bytes};
    ipc::Payload in{bytes};
    child.wait_ready();
    child.go();
    ipc::time_round_trips(state, [&](std::uint64_t seq) {
      out.stamp(seq);
      write_all(child, sockets.parent.get(), out.bytes());
      read_all(child, sockets.parent.get(), in.bytes());
      if (in.seq() != seq) throw ipc::out_of_sequence(seq, in.seq());
    });
    child.stop();
  });
}
BENCHMARK(BM_Latency_UnixSocket)->Apply(ipc::latency_payloads);

void BM_Throughput_UnixSocket(benchmark::State& state) {
  ipc::run(state, [&](std::size_t bytes) {
    auto sockets = socket_pair();
    ipc::Link child{"UnixSocket.stream", bytes, {sockets.child.get()}};
    sockets.child = ipc::UniqueFd{};
    ipc::Payload in{bytes};
    child.set_drain([&] { (void)::recv(sockets.parent.get(), in.bytes().data(), in.bytes().size(), MSG_DONTWAIT); });
    child.wait_ready();
    child.go();
    ipc::time_stream(state, [&](std::uint64_t seq) {
      read_all(child, sockets.parent.get(), in.bytes());
      if (in.seq() != seq) throw ipc::out_of_sequence(seq, in.seq());
    });
    child.stop();
  });
}
BENCHMARK(BM_Throughput_UnixSocket)->Apply(ipc::throughput_payloads);

}  // namespace
