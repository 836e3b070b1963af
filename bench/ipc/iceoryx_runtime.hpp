#pragma once

// What every iceoryx benchmark of prime_ipc shares: the RouDi this binary
// starts itself (one per machine; a foreign one is refused), each process's
// runtime, and the names of its topics. The Iceoryx peer (iceoryx_peer.cpp),
// the 1 kHz loop's iceoryx rows (loop.cpp) and Cyclone DDS's shared memory
// (cyclonedds_peer.cpp) use it.
//
// iceoryx's runtime can be initialised once per process: the parent's lives
// until exit, each child's for one benchmark run.

#include <unistd.h>

#include <cstddef>
#include <string>

#include "harness.hpp"
#include "iceoryx_hoofs/platform/platform_settings.hpp"
#include "iceoryx_posh/capro/service_description.hpp"

namespace prime::bench::ipc::iceoryx {

// Starts this process's RouDi and iceoryx runtime on first use. Statics end
// in the reverse order of their construction, so at exit the runtime says
// goodbye to RouDi before RouDi is stopped. Throws (and tries again on the
// next call) if RouDi cannot be started.
void start_iceoryx();

// A child's runtime is named after its topic, so that the parent knows it.
std::string child_runtime_name(const std::string& topic);

// Starts a child's runtime, named after `topic`.
void start_child_runtime(const std::string& topic);

// A runtime that is killed leaves its socket and lock file in /tmp (iceoryx
// 2.0); the parent removes those of a child it had to kill once it is gone.
class ChildRuntimeFiles {
 public:
  explicit ChildRuntimeFiles(const std::string& topic)
      : socket_{iox::platform::IOX_UDS_SOCKET_PATH_PREFIX + child_runtime_name(topic)},
        lock_{iox::platform::IOX_LOCK_FILE_PATH_PREFIX + child_runtime_name(topic) + ".lock"} {}
  ChildRuntimeFiles(const ChildRuntimeFiles&) = delete;
  ChildRuntimeFiles& operator=(const ChildRuntimeFiles&) = delete;
  ~ChildRuntimeFiles() {
    ::unlink(socket_.c_str());
    ::unlink(lock_.c_str());
  }

 private:
  std::string socket_;
  std::string lock_;
};

// Whether a run on RouDi has failed: its child may have died holding the lock
// of one of its ports, and RouDi then hangs on that lock for good (iceoryx
// 2.0's port locks are not robust), and so would every later run.
inline bool roudi_suspect = false;

// ipc::run for a benchmark whose processes use RouDi: starts RouDi and this
// process's runtime first, and runs nothing more once such a run has failed.
template <class Body>
void run_on_roudi(benchmark::State& state, Body body) {
  ipc::run(state, [&](std::size_t bytes) {
    if (roudi_suspect)
      throw PeerError{"not run: an earlier run on RouDi failed, and RouDi may hang on a lock its child held"};
    start_iceoryx();
    try {
      body(bytes);
    } catch (...) {
      roudi_suspect = true;
      throw;
    }
  });
}

// A fresh instance name per benchmark run, so a run never meets the ports of
// the one before, which RouDi removes only in its next discovery cycle.
std::string new_topic();

// The service of `topic`'s `event` ("ping", "stream"...).
iox::capro::ServiceDescription service(const std::string& topic, const char* event);

}  // namespace prime::bench::ipc::iceoryx
