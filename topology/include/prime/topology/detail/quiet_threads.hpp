#pragma once

#include <pthread.h>
#include <signal.h>

#include <utility>

namespace prime::detail {

// Runs `start`, which starts a thread of Prime's own, with every signal
// blocked on the calling thread, and returns what it returns. The thread
// it starts inherits the mask, so it takes none of the program's signals:
// those go to the program's own threads, to its handler, sigwait or
// signalfd. A program that blocks SIGTERM and reads it from a signalfd,
// after a core started its workers, would otherwise die of the signal
// delivered to a worker (sigwait hides this: it unblocks the signal while
// it waits).
template <class Start>
decltype(auto) with_signals_blocked(Start&& start) {
  sigset_t all, before;
  sigfillset(&all);
  pthread_sigmask(SIG_BLOCK, &all, &before);
  struct Restore {
    const sigset_t& mask;
    ~Restore() { pthread_sigmask(SIG_SETMASK, &mask, nullptr); }
  } const restore{before};
  return std::forward<Start>(start)();
}

}  // namespace prime::detail
