#pragma once

// The `prime` commands: the options they share, their exit codes, and each
// command on a shared-memory domain and (optimus_*) on an Optimus one.

#include <string>
#include <vector>

#include "prime/logic/sample.hpp"
#include "prime/optimus/inspect.hpp"
#include "prime/shm/inspect.hpp"
#include "prime/shm/qos.hpp"

namespace prime::tool {

// What every command is given.
struct Options {
  std::string domain = "robot";
  std::string redis;  // an Optimus domain on this server instead
  bool json = false;
  std::string name;                 // the topic or service
  std::vector<std::string> values;  // pub, call: JSON or field=value words
  std::size_t count = 0;            // echo -n, hz/delay: stop after so many samples (0: no limit)
  double duration = 0;              // seconds to run (0: until Ctrl-C)
  std::size_t window = 100;         // samples hz, bw and delay look at
  double rate = 0;                  // pub: samples per second (0: once)
  double timeout = 5;               // call: seconds; echo: how long to wait for a first sample
  bool all = false;                 // clean: every domain
  std::string owner;                // another user (name or uid) whose shm domain this tool may read and join
};

// From now on Ctrl-C ends the command's loop (ctrl_c_pressed()) instead of
// the process, so it finishes its report.
void finish_on_ctrl_c();
bool ctrl_c_pressed();  // asked by the command's loop, on the main thread
// What such a command exits with: `code`, or kInterrupted when Ctrl-C cut
// it short. One that runs until Ctrl-C (`open_ended`: given no count or
// duration) is done when it comes.
int after_ctrl_c(bool open_ended, int code);

// When echo gives up waiting for a first sample: --timeout after `start`
// (never, for 0); and giving up, saying so, with the exit code for it.
Clock::time_point first_sample_by(const Options& o, Clock::time_point start);
int nothing_published(const Options& o);

// What a command's exit code says.
enum Exit : int { kOk = 0, kFailed = 1, kUsage = 2, kNotFound = 3, kNothing = 4, kUnreachable = 5, kInterrupted = 130 };

// The domain `o` names, as it is now; Errc::not_found when it is not there,
// unreachable when a user not trusted set it up.
shm::RegistrySnapshot snapshot_of(const Options& o);
// How a command joins that domain, as a participant named `participant`.
shm::DomainOptions joining(const Options& o, const std::string& participant);

int shm_domains(const Options& o);
int shm_ls(const Options& o);
int shm_info(const Options& o);
int shm_watch(const Options& o, const std::string& command);  // hz, bw, delay (watch.hpp) on a topic
int shm_echo(const Options& o);
int shm_pub(const Options& o);
int shm_call(const Options& o);
int shm_graph(const Options& o);
int shm_clean(const Options& o);

// The Optimus domain `o` names: its server and credentials (from the URL,
// or PRIME_REDIS_USER and PRIME_REDIS_PASSWORD)...
optimus::Options optimus_options(const Options& o);
// ...and looked at from outside.
optimus::Inspector optimus_inspector(const Options& o);
int optimus_ls(const Options& o);
int optimus_info(const Options& o);
int optimus_watch(const Options& o, const std::string& command);  // hz, bw, delay, echo on a source
int optimus_graph(const Options& o);

}  // namespace prime::tool
