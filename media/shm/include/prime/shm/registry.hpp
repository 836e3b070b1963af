#pragma once

#include <cstdint>
#include <string>
#include <vector>

#include "prime/shm/qos.hpp"

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
    std::uint64_t failed;  // of them, with an error
  };
  std::vector<Participant> participants;
  std::vector<Topic> topics;
  std::vector<Service> services;
};

}  // namespace prime::shm
