#pragma once

#include <any>
#include <deque>
#include <map>
#include <memory>
#include <mutex>
#include <string>

#include "prime/liberty.hpp"
#include "prime/optimus.hpp"
#include "prime/shm.hpp"
#include "prime/system/plan.hpp"
#include "prime/topology/loop.hpp"

namespace prime::system::detail {

// What one process's components share: the cores of the media its plan
// needs, and the in-process end of each topic and service, by name. Made
// and stopped by the Host; read by each component's Context.
struct Links {
  explicit Links(Plan p);  // joins the media the plan's links need
  Links(const Links&) = delete;
  Links& operator=(const Links&) = delete;
  ~Links() { stop(); }

  // Loops first (they publish), then the chains reading inputs (they may
  // call services through a medium), then the media's workers.
  void stop();

  [[nodiscard]] unsigned reach(const std::string& name) const {
    const auto found = plan.reach.find(name);
    return found == plan.reach.end() ? Reach::here : found->second;
  }
  // The name as the media carry it: with the placement's namespace.
  [[nodiscard]] std::string wire_name(const std::string& name) const {
    return plan.ns.empty() ? name : plan.ns + "/" + name;
  }
  [[nodiscard]] Qos topic_qos(const std::string& name, const Qos& declared) const {
    const auto found = plan.topic_qos.find(name);
    return found == plan.topic_qos.end() ? declared : found->second;
  }

  Plan plan;
  liberty::Core local;  // in-process topics, the chains reading inputs, and (without Shm) loops
  std::unique_ptr<shm::Core> shm;          // when a link reaches another process of this machine
  std::unique_ptr<optimus::Core> optimus;  // when one reaches another machine
  std::mutex mutex;
  std::map<std::string, std::any> topics;    // LocalSource<T>: every in-process end of the topic
  std::map<std::string, std::any> shared;    // LocalSource<std::shared_ptr<const T>>: its readers sharing each value
  std::map<std::string, std::any> services;  // std::shared_ptr<LocalService<In, Out>>
  std::map<std::string, std::any> fed;       // FedInput<T>: an input given from outside the plan (Harness::feed_from)
  std::deque<Loop> loops;
  std::deque<std::any> kept;  // what must live as long as the links (a service's handle)
};

}  // namespace prime::system::detail
