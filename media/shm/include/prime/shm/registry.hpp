#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "prime/common/fingerprint.hpp"
#include "prime/shm/qos.hpp"
#include "prime/topology/loop.hpp"

namespace prime::shm {

// What the registry shows of a domain at one moment.
struct RegistrySnapshot {
  struct Participant {
    std::string name;
    std::uint32_t pid;             // as the participant sees itself: in its own pid namespace
    std::uint64_t pid_namespace;   // that namespace (the inode of /proc/<pid>/ns/pid)
    bool alive;                    // it holds its lease (a lock the kernel drops when it dies)
  };
  struct Topic {
    std::string name;
    std::string type;  // Fingerprint::describe()
    TopicQos qos;
    std::uint32_t publisher_pid;  // 0: none alive
    std::string publisher;        // its participant name; empty: none alive
    std::vector<std::uint32_t> subscriber_pids;
    std::uint64_t published;  // sequences so far
    std::string schema;       // its type's description (prime::schema_of)
    Fingerprint fingerprint;  // its type's, whole: what a topic made again with this type must carry
  };
  struct Service {
    std::string name;
    std::string request_type;  // Fingerprint::describe()
    std::string reply_type;
    ServiceQos qos;
    std::uint32_t server_pid;  // 0: none alive
    std::string server;        // its participant name; empty: none alive
    std::vector<std::uint32_t> client_pids;
    std::uint64_t served;  // calls answered
    std::uint64_t failed;  // calls whose block failed
    // Where its requests came from and its answers went: a caller, or (in
    // a linked call) the service before or after it.
    std::uint64_t requests_from_callers;
    std::uint64_t requests_forwarded_in;
    std::uint64_t replies_to_callers;
    std::uint64_t outputs_forwarded_on;
    std::string request_schema;  // the types' descriptions (prime::schema_of)
    std::string reply_schema;
  };
  struct Loop {
    std::string name;
    std::string participant;  // the participant running it, and its pid
    std::uint32_t pid;
    Clock::duration period;
    Clock::duration deadline;
    LoopStats stats;  // as its thread has recorded them so far
  };
  std::vector<Participant> participants;
  std::vector<Topic> topics;
  std::vector<Service> services;
  std::vector<Loop> loops;
};

}  // namespace prime::shm
