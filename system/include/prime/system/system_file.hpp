#pragma once

#include <map>
#include <optional>
#include <set>
#include <string>
#include <string_view>
#include <vector>

#include "prime/system/plan.hpp"
#include "prime/system/registry.hpp"

namespace prime::system {

// What `prime launch` does when a process ends on its own.
enum class Restart { never, on_failure, always };

// One process of a placement: the instances it hosts, the machine it runs on.
struct ProcessSpec {
  std::string name;
  std::vector<std::string> instances{};
  std::string machine = "local";
  std::string executable{};  // empty: the system's
  Restart restart = Restart::never;
  int line = 0;
};

struct PlacementSpec {
  std::string name;
  std::vector<ProcessSpec> processes{};
  int line = 0;
};

// A system file, read (load_system) but not yet checked against the
// components (problems): the instances, the topics' QoS, the machines'
// Redis and the placements. Every entry keeps its line for errors.
//
//   system: robot                  # the Shm domain and Optimus key prefix
//   executable: ./robot            # what each process runs (beside this file)
//   libraries: [./libarm.so]       # components a program loads (beside this file)
//   machines: {base: {redis: tcp://10.0.0.2:6379}}
//   components:
//     planner: {type: robot.planner, params: {gain: 2.0}}
//   topics:
//     sensors/lidar: {capacity: 16, overflow: drop_oldest, expose: true}
//   placements:
//     one: {robot: [sensors, planner, driver]}
//     split: {sensors: [sensors], planner: {components: [planner], restart: on_failure}, driver: [driver]}
struct SystemSpec {
  std::string file;
  std::string domain = "prime";
  std::string executable{};
  std::string ns{};
  // Shared libraries of components a hosting program loads before it
  // checks or hosts (beside the file when relative), with their lines.
  std::vector<std::pair<std::string, int>> libraries{};
  std::vector<Instance> instances{};
  std::map<std::string, int> instance_lines{};  // instance, and "instance.param" for each override
  std::map<std::string, Qos> topics{};
  std::map<std::string, int> exposed{};  // topics published into the Shm domain whatever reads them, with their lines
  std::map<std::string, std::string> redis{};  // per machine
  std::vector<PlacementSpec> placements{};

  [[nodiscard]] const PlacementSpec* placement(std::string_view name) const;
};

// Reads a system file. Throws Failure (Errc::invalid_argument) naming the
// file, the line and what is wrong: YAML it cannot parse, an entry of the
// wrong shape, a value of the wrong kind. `overrides` ("planner.gain=3")
// replace parameters as the command line gives them.
SystemSpec load_system(const std::string& path, const std::vector<std::string>& overrides = {});

// What is wrong with `placement` of the system, against the components
// `registry` knows, each naming the file and line: an unknown component,
// parameter or placement; a parameter of the wrong type; a subscriber whose
// type differs from its publisher's; two publishers on a topic; two
// servers of a service, or a call to a service nobody serves; an instance
// placed in no process or in two; a link between processes whose type
// cannot cross them; a process that needs Redis on a machine without it.
// An exposed topic whose type cannot leave its process. Every program of
// a system must know every component of it: where a link goes depends on
// all its ends.
std::vector<std::string> problems(const SystemSpec& system, const Registry& registry, std::string_view placement);

// Loads the system's libraries of components (dlopen), so that their
// PRIME_COMPONENT registrations join the program's registry. Throws
// Failure (Errc::not_found) naming the file, the line and why one cannot
// be loaded.
void load_libraries(const SystemSpec& system);

// The processes of `placement` in the order to start them: each after the
// processes serving what it calls (as listed, otherwise).
std::vector<std::string> start_order(const SystemSpec& system, const Registry& registry, std::string_view placement);

// The plan of one process of `placement`: its instances and where each of
// their links leads. Throws Failure (Errc::invalid_argument) with the first
// of problems().
Plan plan_of(const SystemSpec& system, const Registry& registry, std::string_view placement, std::string_view process);

}  // namespace prime::system
