#include "prime/system/host.hpp"

#include <set>

namespace prime::system {

namespace detail {

Links::Links(Plan p) : plan{std::move(p)} {
  unsigned reached = 0;
  for (const auto& [name, reach] : plan.reach) reached |= reach;
  if ((reached & Reach::same_machine) || plan.join_domain) {
    // Listed by `prime ls` as the process and the components it hosts:
    // "robot (driver, sensors, planner)"; "planner" for a process named
    // after the one component it hosts.
    std::string participant = plan.process;
    if (!(plan.instances.size() == 1 && plan.instances.front().name == plan.process)) {
      participant += " (";
      for (std::size_t i = 0; i < plan.instances.size(); ++i) participant += (i ? ", " : "") + plan.instances[i].name;
      participant += ")";
    }
    if (participant.size() > 47) participant = plan.process + " (" + std::to_string(plan.instances.size()) + " components)";
    shm = std::make_unique<shm::Core>(plan.shm_domain, shm::DomainOptions{.participant = participant});
  }
  if (reached & Reach::other_machine) {
    if (!plan.redis)
      throw Failure{{Errc::invalid_argument, "process '" + plan.process +
                                                 "' has links to other machines and no Redis to carry them"}};
    optimus = std::make_unique<optimus::Core>(optimus::Options{.url = *plan.redis, .domain = plan.optimus_domain});
  }
}

void Links::stop() {
  for (auto& loop : loops) loop.stop();
  local.stop();  // the chains reading inputs, which may call services through the media
  if (shm) shm->stop();
  if (optimus) optimus->stop();
}

}  // namespace detail

Registry& Registry::global() {
  static Registry registry;
  return registry;
}

void Registry::add(Component component) {
  const auto type = component.type();
  std::scoped_lock lock{mutex_};
  if (!components_.emplace(type, std::move(component)).second)
    throw Failure{{Errc::in_use, "component '" + type + "' is registered twice"}};
}

bool Registry::declare(Component component) noexcept {
  try {
    add(std::move(component));
    return true;
  } catch (const std::exception& e) {
    try {
      std::scoped_lock lock{mutex_};
      problems_.emplace_back(e.what());
    } catch (...) {  // out of memory for the words: the component is missing all the same
    }
    return false;
  }
}

std::vector<std::string> Registry::problems() const {
  std::scoped_lock lock{mutex_};
  return problems_;
}

const Component* Registry::find(std::string_view type) const {
  std::scoped_lock lock{mutex_};
  const auto found = components_.find(type);
  return found == components_.end() ? nullptr : &found->second;
}

std::vector<const Component*> Registry::components() const {
  std::scoped_lock lock{mutex_};
  std::vector<const Component*> all;
  for (const auto& [type, component] : components_) all.push_back(&component);
  return all;
}

std::string param_problem(const Component& component, const Instance& instance) {
  for (const auto& [name, value] : instance.params) {
    const auto where = "component '" + instance.name + "' (" + component.type() + "): parameter '" + name + "'";
    if (name.ends_with(".period_ms")) {
      const auto trigger = name.substr(0, name.size() - std::string_view{".period_ms"}.size());
      if (!component.trigger(trigger)) return where + ": no trigger '" + trigger + "' is declared";
      const auto* ms = std::get_if<std::int64_t>(&value);
      if (!ms) return where + " is an integer (milliseconds), given " + std::string{param_type_name(value.index())};
      if (*ms <= 0 || *ms > 86'400'000) return where + " must be from 1 to 86400000 (a day), given " + std::to_string(*ms);
      continue;
    }
    const auto* declared = component.param(name);
    if (!declared) return where + " is not declared";
    const bool number_from_integer = declared->value.index() == 2 && value.index() == 1;
    if (declared->value.index() != value.index() && !number_from_integer)
      return where + " is " + std::string{param_type_name(declared->value.index())} + ", given " +
             std::string{param_type_name(value.index())};
  }
  return {};
}

Host::Host(Plan plan, const Registry& registry) {
  std::set<std::string> names;
  std::vector<const Component*> components;
  for (auto& instance : plan.instances) {
    const auto* component = registry.find(instance.component);
    if (!component)
      throw Failure{{Errc::not_found, "process '" + plan.process + "': no component '" + instance.component +
                                          "' is registered (instance '" + instance.name + "')"}};
    if (!names.insert(instance.name).second)
      throw Failure{{Errc::invalid_argument, "process '" + plan.process + "': instance '" + instance.name + "' is named twice"}};
    if (auto problem = param_problem(*component, instance); !problem.empty())
      throw Failure{{problem.find(", given ") != std::string::npos ? Errc::type_mismatch : Errc::invalid_argument, problem}};
    for (auto& [name, value] : instance.params)  // an integer given for a number
      if (const auto* declared = component->param(name); declared && declared->value.index() == 2)
        if (const auto* i = std::get_if<std::int64_t>(&value)) value = static_cast<double>(*i);
    components.push_back(component);
  }
  links_ = std::make_unique<detail::Links>(std::move(plan));
  try {
    for (std::size_t i = 0; i < components.size(); ++i) {
      const auto& instance = links_->plan.instances[i];
      contexts_.push_back(std::make_unique<Context>(*components[i], instance, *links_));
      if (!components[i]->builder()) continue;
      try {
        components[i]->builder()(*contexts_.back());
      } catch (const Failure& f) {
        throw Failure{{f.error().code, "building component '" + instance.name + "': " + f.error().message}};
      } catch (const std::exception& e) {
        throw Failure{{Errc::block_failed, "building component '" + instance.name + "': " + e.what()}};
      }
    }
  } catch (...) {
    links_->stop();
    throw;
  }
}

Host::~Host() { stop(); }

void Host::stop() { links_->stop(); }

}  // namespace prime::system
