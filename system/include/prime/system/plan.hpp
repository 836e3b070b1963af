#pragma once

#include <map>
#include <optional>
#include <string>
#include <vector>

#include "prime/system/component.hpp"

namespace prime::system {

// Where the other ends of a link are, seen from one process: in it, in
// another process of its machine (Shm), on another machine (Optimus). An
// output or a service goes to every medium one of its other ends needs; an
// input or a call comes from exactly one.
enum Reach : unsigned {
  here = 1u << 0,
  same_machine = 1u << 1,
  other_machine = 1u << 2,
};

// One instance of a registered component, with its parameters' overrides.
struct Instance {
  std::string name;       // unique in the system: "planner", "left_camera"
  std::string component;  // the registered type
  std::map<std::string, ParamValue> params{};
};

// What is wrong with an instance's parameter overrides, for the component
// it names: "" when nothing is. Integers are taken for number parameters.
std::string param_problem(const Component& component, const Instance& instance);

// What one process hosts and how each of its links goes: what a system file
// and a placement decide for it (SystemFile::plan), or a test by hand.
struct Plan {
  std::string process = "main";
  std::vector<Instance> instances{};
  // Per topic or service name (as the ports name them): where the other
  // ends are. A name not listed is linked in this process.
  std::map<std::string, unsigned> reach{};
  // The topic's QoS, where the system sets it for every end (otherwise each
  // end's declaration, and across processes both must agree).
  std::map<std::string, Qos> topic_qos{};
  // Prefix of every topic and service name as the media see them
  // ("robot1" makes "sensors/lidar" "robot1/sensors/lidar").
  std::string ns{};
  std::string shm_domain = "prime";
  // Join the Shm domain even with no link through it, so that `prime ls`
  // lists the process, its components and its loops (as a launched
  // process does).
  bool join_domain = false;
  // Redis, for links to other machines: "tcp://host:port".
  std::optional<std::string> redis{};
  std::string optimus_domain = "prime";
};

}  // namespace prime::system
