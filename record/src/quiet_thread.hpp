// A library's own thread that takes none of the program's signals.
#pragma once

#include <pthread.h>
#include <signal.h>

#include <thread>
#include <utility>

namespace prime::record {

// Starts `f` on a thread with every signal blocked, so that Ctrl-C and the
// like go to the program's threads (its handler, or its sigwait), never to
// a writer of ours: a program that takes SIGINT synchronously would
// otherwise lose it to this thread's default action or handler.
template <class F>
std::thread quiet_thread(F&& f) {
  sigset_t all, before;
  sigfillset(&all);
  pthread_sigmask(SIG_BLOCK, &all, &before);
  struct Restore {
    const sigset_t& mask;
    ~Restore() { pthread_sigmask(SIG_SETMASK, &mask, nullptr); }
  } restore{before};
  return std::thread{std::forward<F>(f)};  // inherits the mask
}

}  // namespace prime::record
