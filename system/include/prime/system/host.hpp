#pragma once

#include <memory>
#include <string>
#include <vector>

#include "prime/system/context.hpp"
#include "prime/system/plan.hpp"
#include "prime/system/registry.hpp"

namespace prime::system {

// Hosts the instances a plan gives one process: joins the media its links
// need, builds each instance with a Context whose ports lead where the plan
// says, and keeps them running until it is stopped or destroyed.
//
// Throws Errc::not_found for a component the registry does not have,
// Errc::invalid_argument for a parameter it does not declare (or an
// instance named twice), Errc::type_mismatch for a parameter of another
// type; and what a build throws, with the instance's name.
class Host {
 public:
  explicit Host(Plan plan, const Registry& registry = Registry::global());
  Host(const Host&) = delete;
  Host& operator=(const Host&) = delete;
  ~Host();

  // Stops every loop, link and worker of the process's components. Idempotent.
  void stop();

  [[nodiscard]] const Plan& plan() const noexcept { return links_->plan; }
  // The process's in-process core: its errors(), its chains.
  [[nodiscard]] liberty::Core& local() noexcept { return links_->local; }
  // The loops the components run, in the order they started.
  [[nodiscard]] const std::deque<Loop>& loops() const noexcept { return links_->loops; }

 protected:
  [[nodiscard]] detail::Links& links() noexcept { return *links_; }

 private:
  std::unique_ptr<detail::Links> links_;
  std::vector<std::unique_ptr<Context>> contexts_;
};

}  // namespace prime::system
